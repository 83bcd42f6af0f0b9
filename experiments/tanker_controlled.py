"""S4: the shuttle under the nonlinear compensator (law B) and law A, in the four
environments of the spec, with the acceptance list (after 3000 s: |d - d_ref| <
0.5 m, |y2| < 0.5 deg; hull clearance > 0 throughout; actuator limits respected),
a model-mismatch check (the compensator believes C_Y and the wind areas 20 % off)
and the solver choice (tsit5 vs dopri5 vs kvaerno5 on the same scene: compile and
run time, medians of repeats, ratios from this run).

Writes results/tanker_controlled.{md,csv} and one figure per environment,
results/tanker_controlled_<env>.png (--quick: results/quick/, names ending in
`_quick`).

`--mismatch` runs the model-mismatch study alone instead: the compensator's model
has C_Y and the wind areas each 20 % high or low (four combinations), law B
without integral action and with K_I = omega^3/10, in every environment (--quick:
15 m/s wind from 180 deg only); writes results/tanker_controlled_mismatch.{md,csv}.

    python experiments/tanker_controlled.py [--quick] [--mismatch]
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


import jax
import jax.numpy as jnp
import numpy as np
from _common import clock, results_dir, run_study, set_quick, stamp_file, write_report

import jaxstring as js
from jaxstring.tandem import plot as tp
from jaxstring.tandem.analysis import CONTROLLED_METRICS, controlled_metrics
from jaxstring.tandem.scenes import (
    ENVIRONMENTS,
    tandem_controlled,
    with_model_mismatch,
)


KEYS = CONTROLLED_METRICS


def row(law, env, m, run_s):
    """One markdown row of the acceptance table."""
    cells = (
        law,
        env,
        f"{m['span_error']:.2e}",
        f"{m['heading_error']:.2e}",
        f"{m['span_min']:.2f}",
        f"{m['clearance_min']:.1f}",
        f"{m['X_peak'] / 1e3:.0f}",
        f"{m['N_peak']:.3g}",
        f"{m['psi1_final']:.2f}",
        f"{m['X_final'] / 1e3:.0f}",
        f"{m['N_final']:.3g}",
        str(m["ok"]),
        f"{run_s:.2f}",
    )
    return "| " + " | ".join(cells) + " |"


def _cells(values):
    return [f"{v:.6g}" if isinstance(v, float) else str(v) for v in values]


def run(scene, solver="tsit5", repeats=1, n_save=None):
    n_save = n_save or int(float(scene.t1) / 2) + 1
    ts = jnp.linspace(0.0, float(scene.t1), n_save)
    walls = []
    for _ in range(repeats + 1):
        traj, wall, _ = clock(
            lambda: jax.block_until_ready(
                js.simulate(scene, solver, rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6)
            )
        )
        walls.append(wall)
    run_s = float(np.median(walls[1:]))
    return traj, walls[0] - run_s, run_s


def mismatched(scene, factor_cy=1.2, factor_wind=0.8):
    """The same scene, but the compensator's internal model has C_Y x factor_cy and
    wind areas x factor_wind on both hulls (spec S4 recommended test)."""
    return with_model_mismatch(scene, factor_cy, factor_wind)


FACTORS = ((1.2, 0.8), (0.8, 1.2), (1.2, 1.2), (0.8, 0.8))


def mismatch_study(quick=False, omega=0.05, t1=6000.0):
    """Law B with a wrong internal model, without and with integral action
    (K_I = omega^3/10, s^-3): the S4 acceptance after 3000 s."""
    sfx = "_quick" if quick else ""
    K_I = omega**3 / 10
    envs = ("wind15_180",) if quick else tuple(ENVIRONMENTS)
    lines = [
        "Law B believes C_Y and the wind areas off by the factors; the plant keeps "
        f"the nominal ones. K_I = omega^3/10 = {K_I:.3g} s^-3 (omega = {omega} "
        "rad/s) on both channels, anti-windup by back-calculation "
        "(K_aw = 1/omega^2).",
        "",
        "| env | C_Y x | wind area x | K_I s^-3 | |d-dref| m | |y2| deg | d_min m "
        "| clearance m | |X|max kN | psi1 end deg | X end kN | ok | run s |",
        "|" + "---|" * 13,
    ]
    rows = []
    for env in envs:
        for fc, fw in FACTORS:
            for k_i in (None, K_I):
                sc = with_model_mismatch(
                    tandem_controlled(env=env, t1=t1, omega=omega, K_I=k_i), fc, fw
                )
                ctl = sc.effects[-1]
                traj, _, run_s = run(sc)
                m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max)
                k_txt = "0" if k_i is None else f"{k_i:.3g}"
                lines.append(
                    f"| {env} | {fc} | {fw} | {k_txt} | {m['span_error']:.3g} | "
                    f"{m['heading_error']:.3g} | {m['span_min']:.2f} | "
                    f"{m['clearance_min']:.1f} | {m['X_peak'] / 1e3:.0f} | "
                    f"{m['psi1_final']:.2f} | {m['X_final'] / 1e3:.0f} | "
                    f"{m['ok']} | {run_s:.2f} |"
                )
                rows.append((env, fc, fw, 0.0 if k_i is None else k_i, m))
    csv = ["env,factor_C_Y,factor_wind_area,K_I," + ",".join(KEYS)]
    for env, fc, fw, k_i, m in rows:
        csv.append(",".join(_cells((env, fc, fw, k_i, *[m[k] for k in KEYS]))))
    write_report(
        f"tanker_controlled_mismatch{sfx}",
        "S4 with model mismatch, without and with integral action",
        "\n".join(lines),
        csv,
    )
    return rows


def main(quick=False, mismatch=False):
    set_quick(quick)
    if mismatch:
        return mismatch_study(quick)
    sfx = "_quick" if quick else ""
    t1 = 4000.0 if quick else 6000.0
    rows, lines, compile_s = [], [], {}
    header = (
        "| law | env | |d-dref| m | |y2| deg | d_min m | clearance m | |X|max kN "
        "| |N|max N m | psi1 end deg | X end kN | N end N m | ok | run s |"
    )
    lines += [header, "|" + "---|" * 13]
    laws = ("B",) if quick else ("B", "A")
    for law in laws:
        for env in ENVIRONMENTS:
            sc = tandem_controlled(env=env, law=law, t1=t1)
            ctl = sc.effects[-1]
            traj, comp, run_s = run(sc)
            compile_s.setdefault((law, "wind" in env), comp)
            m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max)
            rows.append((law, env, *[m[k] for k in KEYS]))
            lines.append(row(law, env, m, run_s))
            if law == "B":
                png = results_dir() / f"tanker_controlled_{env}{sfx}.png"
                tp.tandem_figure(
                    traj, sc.model, str(png), title=f"S4 law B, {env}",
                    d_ref=float(ctl.d_ref),
                )  # fmt: skip
                stamp_file(png)
    # Model mismatch (no integral action: the compensator has no integral term).
    lines += [
        "",
        "Model mismatch (law B believes C_Y x1.2 and wind areas x0.8; "
        "no integral action):",
        "",
        header,
        "|" + "---|" * 13,
    ]
    for env in ("wind15_90",) if quick else tuple(ENVIRONMENTS):
        sc = mismatched(tandem_controlled(env=env, t1=t1))
        ctl = sc.effects[-1]
        traj, comp, run_s = run(sc)
        m = controlled_metrics(traj, float(ctl.d_ref), ctl.X_max, ctl.N_max)
        lines.append(row("B*", env, m, run_s))
        rows.append(("B-mismatch", env, *[m[k] for k in KEYS]))
    # Solver choice on one scene.
    lines += [
        "",
        "Solver choice (law B, wind15_90, rtol = atol = 1e-8):",
        "",
        "| solver | steps | compile s | run s (median) | run / tsit5 |",
        "|---|---|---|---|---|",
    ]
    sc = tandem_controlled(env="wind15_90", t1=t1)
    ref = None
    for solver in ("tsit5", "dopri5", "kvaerno5"):
        traj, comp, run_s = run(sc, solver, repeats=1 if quick else 3)
        if solver == "tsit5":  # compiled already by the first windy run above
            comp = compile_s[("B", True)]
        ref = run_s if ref is None else ref
        lines.append(
            f"| {solver} | {int(traj.stats['num_steps'])} | {comp:.1f} | "
            f"{run_s:.3f} | {run_s / ref:.1f} |"
        )
    csv = ["law,env," + ",".join(KEYS)] + [",".join(_cells(r)) for r in rows]
    write_report(
        f"tanker_controlled{sfx}", "S4 controlled tandem", "\n".join(lines), csv
    )


if __name__ == "__main__":
    run_study(
        main,
        mismatch=dict(
            action="store_true",
            help="only the model-mismatch study, without and with integral action",
        ),
    )
