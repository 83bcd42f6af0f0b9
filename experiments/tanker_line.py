"""The hawser as a real line: what mass, weight and drag of the line change in the
tandem, and what they cost.

1. Stability of the aligned equilibrium (spec S2): the leading eigenvalue pair
   with the massless hawser, with a light line (the massless limit) and with a
   0.16 m nylon line (25 kg/m, sinks at 43 N/m in water) of N = 4, 8, 16 nodes,
   with and without drag. Coupled equilibria from Newton on the full vector field.
2. Fishtailing (spec S3a): the limit cycle from the perturbed aligned state,
   massless hawser (tsit5, as `jaxstring run tandem-fishtail`) against the line
   (implicit solvers: the line's axial mode is at ~120 rad/s), with period, yaw
   amplitudes, span and peak tension, and the cost: compile and run time apart,
   steps, and run-time ratios measured in this process.

3. With --controlled (a separate run): the S4 scenes with the line in place of
   the hawser, the nonlinear compensator keeping the massless hawser as its model
   of the line, against the S4 acceptance list, for all four environments.

Writes results/tanker_line.{md,csv,png} and, with --controlled,
results/tanker_line_controlled.{md,csv} (--quick: results/quick/, names ending in
`_quick`).

    python experiments/tanker_line.py [--quick] [--controlled]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


import jax
import jax.numpy as jnp
import numpy as np
from _common import (
    results_file,
    run_study,
    savefig,
    set_quick,
    stamp_markdown,
    timed_wall_cpu,
    timing_fields,
)

import jaxstring as js
from jaxstring.tandem.analysis import measure_limit_cycle
from jaxstring.tandem.line import line_equilibrium, with_line
from jaxstring.tandem.scenes import tandem_fishtail


LIGHT = dict(mass_per_length=0.01, gravity=False, c_n=0.0, c_t=0.0)


def _field(y, scene):
    return scene.vector_field(0.0, y)


def _leading(scene, y):
    J = jax.jit(jax.jacfwd(_field))(y, scene)
    ev = np.linalg.eigvals(np.asarray(J))
    ev = ev[np.argsort(-ev.real)]
    return ev[0], float(np.max(np.abs(ev)))


def stability_rows(quick):
    base = tandem_fishtail(perturbation_deg=0.0)
    lam0, fast0 = _leading(base, base.y0)
    rows = [
        (
            "massless hawser",
            0,
            lam0,
            fast0,
            float(base.observables(base.y0)["span"]),
            0.0,
        )
    ]
    cases = [("light line (0.01 kg/m, no weight, no drag)", 8, LIGHT)]
    for N in (4, 8) if quick else (4, 8, 16):
        cases.append(("nylon line, drag", N, {}))
    cases.append(("nylon line, no drag", 8, dict(c_n=0.0, c_t=0.0)))
    for label, N, kw in cases:
        sc = with_line(base, N=N, **kw)
        y, res = line_equilibrium(sc)
        obs = sc.observables(y)
        lam, fast = _leading(sc, y)
        rows.append((label, N, lam, fast, float(obs["span"]), float(obs["sag"])))
        print(
            f"{label:<45} N={N:<3} lambda = {lam:.5e}  max|lambda| = {fast:.1f}"
            f"  span {float(obs['span']):.3f} m  sag {float(obs['sag']):.2f} m"
            f"  (residual {res:.1e})",
            flush=True,
        )
    return rows, lam0


def _timed(scene, solver, tol, ts):
    return timed_wall_cpu(
        lambda: js.simulate(
            scene, solver, rtol=tol, atol=tol, ts=ts, max_steps=2_000_000
        ),
        1,
    )


def fishtail_rows(quick):
    t1 = 20000.0 if quick else 60000.0
    ts = jnp.linspace(0.0, t1, int(t1 / 10) + 1)
    cases = [("massless", 0, "tsit5", 1e-8)]
    if quick:
        cases += [("line", 4, "rodas5p", 1e-6)]
    else:
        cases += [
            ("line", 8, "rodas5p", 1e-7),
            ("line", 8, "rodas5p", 1e-8),
            ("line", 8, "kvaerno5", 1e-8),
            ("line", 16, "rodas5p", 1e-8),
        ]
    rows, trajs = [], {}
    for hawser, N, solver, tol in cases:
        opts = None if hawser == "massless" else {"N": N}
        sc = tandem_fishtail(t1=t1, hawser=hawser, line_options=opts)
        traj, compile_s, run, cpu = _timed(sc, solver, tol, ts)
        m = measure_limit_cycle(traj, 0.6 * t1) if traj.ok else {}
        rows.append(
            dict(
                hawser=hawser,
                N=N,
                solver=solver,
                tol=tol,
                **timing_fields(traj, compile_s, run, cpu),
                **{k: float(v) for k, v in m.items()},
            )
        )
        trajs[(hawser, N, solver, tol)] = traj
        print(
            f"{hawser:<8} N={N:<3} {solver:<9} tol {tol:.0e}: {traj.status}, "
            f"{rows[-1]['steps']} steps, compile {compile_s:.1f} s, run {run:.2f} s "
            f"(CPU {cpu:.2f} s); "
            + ", ".join(f"{k} {float(v):.4g}" for k, v in m.items()),
            flush=True,
        )
    return rows, trajs, t1


def write(rows_s, lam0, rows_f, trajs, t1, quick):
    import matplotlib.pyplot as plt

    sfx = "_quick" if quick else ""
    base_run = rows_f[0]["run_s"]
    keys = "period shuttle_yaw fpso_yaw lateral_excursion span_min tension_max".split()
    with results_file(f"tanker_line{sfx}.csv") as f:
        f.write(
            "hawser,N,solver,tol,status,steps,compile_s,run_s,cpu_s,"
            + ",".join(keys)
            + "\n"
        )
        for r in rows_f:
            f.write(
                ",".join(
                    str(r.get(k, ""))
                    for k in [
                        "hawser",
                        "N",
                        "solver",
                        "tol",
                        "status",
                        "steps",
                        "compile_s",
                        "run_s",
                        "cpu_s",
                        *keys,
                    ]
                )
                + "\n"
            )
    lines = [
        "# The hawser as a line with mass and drag",
        "",
        stamp_markdown(),
        "",
        "## Aligned equilibrium, current 1 m/s (spec S2)",
        "",
        "| hawser | N | leading eigenvalue (1/s) | vs massless "
        "| max abs(lambda) (1/s) | span m | sag m |",
        "|---|---|---|---|---|---|---|",
    ]
    for label, N, lam, fast, span, sag in rows_s:
        rel = abs(lam - lam0) / abs(lam0)
        lines.append(
            f"| {label} | {N or '-'} | {lam.real:.4e} {lam.imag:+.4e} i | "
            f"{rel:.1e} | {fast:.3g} | {span:.3f} | {sag:.2f} |"
        )
    lines += [
        "",
        "Spec [P]: +7.17e-4 +- 1.852e-3 i. The line is L = l0 = 80 m, EA = k_h l0 = "
        "1.6e7 N (the massless hawser's small-stretch stiffness), d = 0.16 m, "
        "25 kg/m, C_a = 1, drag c_n = 1, c_t = 0.1 on the projected area, in the "
        "vessels' current.",
        "",
        f"## Fishtailing limit cycle (spec S3a), {t1:.0f} s, measured over t > "
        f"{0.6 * t1:.0f} s",
        "",
        "| hawser | N | solver | tol | status | steps | compile s | run s | CPU s | "
        "run / massless | period s | shuttle yaw deg | FPSO yaw deg | lateral m | "
        "span min m | T max kN |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows_f:
        vals = [r.get(k, float("nan")) for k in keys]
        lines.append(
            f"| {r['hawser']} | {r['N'] or '-'} | {r['solver']} | {r['tol']:.0e} | "
            f"{r['status']} | {r['steps']} | {r['compile_s']:.1f} | {r['run_s']:.2f} | "
            f"{r['cpu_s']:.2f} | {r['run_s'] / base_run:.0f}x | {vals[0]:.0f} | "
            f"{vals[1]:.2f} | {vals[2]:.2f} | {vals[3]:.1f} | {vals[4]:.1f} | "
            f"{vals[5] / 1e3:.0f} |"
        )
    lines += [
        "",
        "Spec S3a (massless hawser): period 3400-3500 s, shuttle yaw 13-18 deg, FPSO "
        "yaw 2-4 deg, lateral 150-175 m, span min 29-60 m, T max 0.8-0.9 MN.",
        "The massless run uses tsit5 (the massless tandem is not stiff); the line's "
        "axial mode (~120 rad/s) needs an implicit solver, and the snap loads when "
        "the slack line comes taut set the step size.",
    ]
    text = "\n".join(lines) + "\n"
    with results_file(f"tanker_line{sfx}.md") as f:
        f.write(text)
    print(text)

    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for (hawser, N, solver, tol), traj in trajs.items():
        if not traj.ok:
            continue
        t = np.asarray(traj.ts)
        lab = "massless" if hawser == "massless" else f"line N={N} {solver} {tol:.0e}"
        axes[0].plot(t, np.degrees(np.asarray(traj.headings)[:, 1]), lw=0.8, label=lab)
        axes[1].plot(t, np.asarray(traj.span), lw=0.8)
        axes[2].plot(t, np.asarray(traj.tension) / 1e3, lw=0.8)
    axes[0].set_ylabel("shuttle heading, deg")
    axes[1].set_ylabel("span, m")
    axes[2].set_ylabel("tension, kN")
    axes[2].set_xlabel("t, s")
    axes[0].legend(fontsize=7)
    fig.suptitle("Fishtailing: massless hawser vs a line with mass and drag")
    fig.tight_layout()
    savefig(fig, f"tanker_line{sfx}", dpi=110, tight=False)
    plt.close(fig)


def controlled_study(quick):
    from jaxstring.tandem.analysis import CONTROLLED_METRICS, controlled_metrics
    from jaxstring.tandem.scenes import ENVIRONMENTS, tandem_controlled

    set_quick(quick)
    t1 = 4000.0 if quick else 6000.0
    sfx = "_quick" if quick else ""
    keys = list(CONTROLLED_METRICS)
    rows = []
    for env in ENVIRONMENTS:
        for hawser, solver, tol in (
            ("massless", "tsit5", 1e-8),
            ("line", "rodas5p", 1e-7),
        ):
            sc = tandem_controlled(env=env, t1=t1, hawser=hawser)
            ctl = [e for e in sc.effects if hasattr(e, "d_ref")][0]
            ts = jnp.linspace(0.0, t1, int(t1 / 2) + 1)
            traj, compile_s, run, cpu = _timed(sc, solver, tol, ts)
            m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max)
            rows.append(
                dict(
                    env=env,
                    hawser=hawser,
                    solver=solver,
                    **timing_fields(traj, compile_s, run, cpu),
                    **{k: m[k] for k in keys},
                )
            )
            print(rows[-1], flush=True)
    head = [
        "env",
        "hawser",
        "solver",
        "status",
        "steps",
        "compile_s",
        "run_s",
        "cpu_s",
        *keys,
    ]
    with results_file(f"tanker_line_controlled{sfx}.csv") as f:
        f.write(",".join(head) + "\n")
        for r in rows:
            f.write(",".join(str(r[k]) for k in head) + "\n")
    lines = [
        "# S4 with the hawser as a line (mass, weight, drag)",
        "",
        stamp_markdown(),
        "",
        f"_{t1:.0f} s, acceptance after 3000 s (span error < 0.5 m, heading error "
        "< 0.5 deg, no hull contact, actuator limits); the compensator's internal "
        "model keeps the massless hawser_",
        "",
        "| env | hawser | solver | status | steps | compile s | run s | CPU s | "
        "span err m | heading err deg | span min m | clearance min m | X peak kN | "
        "psi1 end deg | X end kN | ok |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['env']} | {r['hawser']} | {r['solver']} | {r['status']} | "
            f"{r['steps']} | {r['compile_s']:.1f} | {r['run_s']:.2f} | "
            f"{r['cpu_s']:.2f} | {r['span_error']:.3f} | {r['heading_error']:.4f} | "
            f"{r['span_min']:.2f} | {r['clearance_min']:.1f} | "
            f"{r['X_peak'] / 1e3:.0f} | {r['psi1_final']:.2f} | "
            f"{r['X_final'] / 1e3:.0f} | {r['ok']} |"
        )
    text = "\n".join(lines) + "\n"
    with results_file(f"tanker_line_controlled{sfx}.md") as f:
        f.write(text)
    print(text)


def main(quick=False, controlled=False):
    if controlled:
        return controlled_study(quick)
    set_quick(quick)
    rows_s, lam0 = stability_rows(quick)
    rows_f, trajs, t1 = fishtail_rows(quick)
    write(rows_s, lam0, rows_f, trajs, t1, quick)


if __name__ == "__main__":
    run_study(
        main,
        controlled=dict(
            action="store_true", help="only part 3: the S4 scenes with the line"
        ),
    )
