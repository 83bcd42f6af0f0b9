"""Slack and snap: the string pendulum released above the horizontal goes slack and
snaps taut, under the sharp tension-only law and the smoothed one.

Question: where do an error-controlled solver's steps go when the string goes slack
and snaps taut, what does the smoothed tension-only law (`Slack(smoothing=eps_s)`,
the onset of tension blended over strains [0, eps_s]) save in every formulation, and
how much does it change the answer? Cases (alpha = 0.01, rtol = atol = 1e-6, 2 s,
200k steps at most): EA = 1e8 N released from 3 pi/4 ("snap"), EA = 1e6 N released
from 170 deg ("170deg"). Each run is compiled on a 10 ms span of the same scene
first (`compile_s`); `run_s` and `cpu_s` are one full run (wall and process CPU).
The CVODE-numba peer (jaxstring/testing/peers.py, sharp law) runs the same cases.

Error: the largest end-mass distance over 41 save times from Rodas5P at
rtol = atol = 1e-10 with eps_s = 1e-9, the stand-in for the sharp law (whose own
tight solve does not complete, see the notes); the smoothing table measures that
stand-in and each eps_s against it at k = 10.

Output: experiments/results/slack_snap.{md,csv,png}, slack_snap_smoothing.{md,csv},
slack_snap_steps.csv (and slack_snap_k160.{md,csv} with --k_large 160;
slack_snap_gradients.{md,csv} with --gradients_only: forward mode and error-controlled
sensitivities against central differences through snaps). Runtime:
27 min with --k_large 160 on a shared 2-core machine at load 15-20 (--quick: k = 10).
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
if __name__ == "__main__":  # as a script only: importing it changes nothing
    os.environ.setdefault("EQX_ON_ERROR", "nan")

import math
import sys

import numpy as np


sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from harness import clock  # noqa: E402

import jaxstring as js  # noqa: E402
from jaxstring.pendulum.scenes import SLACK_SMOOTHING  # noqa: E402


CASES = {
    "snap": dict(EA=1e8, theta0=3 * math.pi / 4),
    "170deg": dict(EA=1e6, theta0=math.radians(170)),
}
FORMULATIONS = ("displacement", "natural", "angle")
# The preset solver of each formulation: BDF in displacement variables (where
# Rosenbrock methods lose accuracy, jaxstring/_presets.py), Rodas5P in
# natural variables.
SOLVERS = {
    "displacement": ("bdf",),
    "natural": ("rodas5p",),
    "angle": ("rodas5p",),
}
TOL = 1e-6
T1 = 2.0
MAX_STEPS = 200_000
REF_TOL = 1e-10
REF_SMOOTHING = 1e-9
N_SAVE = 41
REPEATS = 3
REPEAT_BUDGET_S = 10.0


def scene(formulation, case, k, smoothing, t1=T1):
    return js.string_pendulum(
        formulation=formulation,
        k=k,
        alpha=0.01,
        t1=t1,
        effects=("gravity", "kelvin_voigt", js.Slack(smoothing=smoothing)),
        **CASES[case],
    )


def run(
    formulation, case, k, smoothing, solver, rtol=TOL, max_steps=MAX_STEPS, repeats=1
):
    """Compile on a 10 ms span, then timed full runs: a result row. The times are
    the least of `repeats` runs (runs after one that took over `REPEAT_BUDGET_S`
    are skipped)."""
    ts = lambda t1: jnp.linspace(0.0, t1, N_SAVE)
    kw = dict(rtol=rtol, atol=rtol, max_steps=max_steps)

    def compile_short():
        short = scene(formulation, case, k, smoothing, t1=0.01)
        jax.block_until_ready(js.simulate(short, solver, ts=ts(0.01), **kw).ys)

    _, compile_s, _ = clock(compile_short)
    sc = scene(formulation, case, k, smoothing)
    run_s = cpu_s = math.inf
    for _ in range(repeats):
        traj, wall, cpu = clock(
            lambda: jax.block_until_ready(js.simulate(sc, solver, ts=ts(T1), **kw))
        )
        run_s, cpu_s = min(run_s, wall), min(cpu_s, cpu)
        if wall > REPEAT_BUDGET_S:
            break
    return dict(
        ok=traj.ok,
        status=traj.status[:40],
        steps=int(traj.stats["num_accepted_steps"]),
        rejected=int(traj.stats["num_rejected_steps"]),
        compile_s=compile_s,
        run_s=run_s,
        cpu_s=cpu_s,
        end=np.asarray(traj.end_mass) if traj.ok else None,
    )


def reference(formulation, case, k, smoothing=REF_SMOOTHING, rtol=REF_TOL):
    traj, wall, _ = clock(
        lambda: js.simulate(
            scene(formulation, case, k, smoothing),
            "rodas5p",
            rtol=rtol,
            atol=rtol,
            ts=jnp.linspace(0.0, T1, N_SAVE),
            max_steps=2_000_000,
        )
    )
    print(
        f"reference {formulation} {case} k={k} eps_s={smoothing:g} rtol={rtol:g}: "
        f"{traj.status}, {int(traj.stats['num_accepted_steps'])} steps, "
        f"{wall:.1f} s",
        flush=True,
    )
    return np.asarray(traj.end_mass) if traj.ok else None


def run_cvode(formulation, case, k):
    """The CVODE-numba peer with the sharp law (band Jacobian: analytic in
    displacement variables, CVODE's difference quotients otherwise)."""
    from jaxstring.testing import peers

    c = CASES[case]
    peer = peers.make_rhs(formulation, k=k, EA=c["EA"], alpha=0.01, slack=True)
    jac = "analytic" if peer.jac is not None else "dq"
    ts = np.linspace(0.0, T1, N_SAVE)
    y0 = peer.initial_state(c["theta0"])
    compile_s = peer.warmup()
    # CVODE's step limit holds between two output times.
    per_output = MAX_STEPS // (N_SAVE - 1)
    out, run_s, cpu_s = clock(
        lambda: peers.cvode_solve(
            peer, ts, y0, rtol=TOL, atol=TOL, jac=jac, max_num_steps=per_output
        )
    )
    return dict(
        ok=out["ok"],
        status="success" if out["ok"] else out["message"][:40],
        steps=None,
        rejected=None,
        nfev=out["nfev"],
        compile_s=compile_s,
        run_s=run_s,
        cpu_s=cpu_s,
        end=peer.end_mass(out["ys"]) if out["ok"] else None,
    )


def step_log(formulation, case, k, smoothing, solver, rtol=TOL):
    """Every accepted step of one solve: times, step sizes, and the number of
    tension points whose state (taut: eps > 0) changed over each step."""
    import diffrax as dfx

    from jaxstring._integrate import solve_scene
    from jaxstring._solve_config import SolveConfig

    sc = scene(formulation, case, k, smoothing)
    # `simulate`'s solver, step control and projection, saved at every step
    config = SolveConfig(solver=solver, rtol=rtol, atol=rtol, max_steps=MAX_STEPS)

    @jax.jit
    def solve(sc):
        strain = lambda t, y, a: a.model.strain(y)[0]
        sol = solve_scene(sc, config, lambda _: dfx.SaveAt(steps=True, fn=strain))
        return sol.ts, sol.ys

    ts, eps = solve(sc)
    ts, eps = np.asarray(ts), np.asarray(eps)
    keep = np.isfinite(ts)
    ts, eps = ts[keep], eps[keep]
    h = np.diff(np.concatenate([[0.0], ts]))
    taut = eps > 0
    changes = np.concatenate([[0], np.sum(taut[1:] != taut[:-1], axis=1)])
    return ts, h, changes


COLUMNS = [
    "case",
    "formulation",
    "k",
    "law",
    "solver",
    "ok",
    "status",
    "steps",
    "rejected",
    "compile_s",
    "run_s",
    "cpu_s",
    "error_m",
]


def _row(case, f, k, law, solver, r, ref):
    row = dict(case=case, formulation=f, k=k, law=law, solver=solver, **r)
    row["error_m"] = _error(r["end"], ref)
    print(_line(row), flush=True)
    return row


def main(
    quick=False,
    k=None,
    k_large=None,
    smoothing=None,
    cvode=True,
    figure=True,
    large_only=False,
    gradients_only=False,
    repeats=None,
):
    from _common import set_quick, write_table

    set_quick(quick)
    repeats = repeats or (1 if quick else REPEATS)
    if smoothing is None:
        smoothing = SLACK_SMOOTHING["angle"]
    if gradients_only:
        return gradient_study(quick)
    if large_only:
        if not k_large:
            raise ValueError("`large_only` needs `k_large`.")
        return large_study(k_large, smoothing, repeats)
    k = k or (10 if quick else 40)
    laws = (("sharp", 0.0), ("smooth", smoothing))
    rows = []
    for case in CASES:
        for f in FORMULATIONS:
            # No tight reference in displacement variables: Rodas5P loses accuracy
            # there, and BDF/Kvaerno5 at rtol 1e-10 do not complete in minutes.
            ref = None if f == "displacement" else reference(f, case, k)
            for solver in SOLVERS[f]:
                for law, eps_s in laws:
                    r = run(f, case, k, eps_s, solver, repeats=repeats)
                    rows.append(_row(case, f, k, law, solver, r, ref))
            if cvode:
                r = run_cvode(f, case, k)
                rows.append(_row(case, f, k, "sharp", "cvode-numba", r, ref))
    title = (
        "Slack and snap: sharp and smoothed tension-only law "
        f"(eps_s = {smoothing:g}), rtol = atol = {TOL:g}, t1 = {T1:g} s"
    )
    notes = [
        "steps, rejected: accepted and rejected steps (CVODE: not counted here).",
        f"run_s, cpu_s: the least of up to {repeats} full runs after compilation "
        f"(wall, process CPU), s; one run where it took over {REPEAT_BUDGET_S:g} s.",
        f"error_m: largest end-mass distance over {N_SAVE} save times from "
        f"(natural variables only) Rodas5P at rtol = atol = {REF_TOL:g} with "
        f"eps_s = {REF_SMOOTHING:g} "
        "(the smoothing table bounds its distance to the sharp law).",
    ]
    write_table("slack_snap", rows, COLUMNS, title, notes=notes)
    smoothing_table(smoothing, k=10)
    if figure:
        step_figure(smoothing, k)
    if k_large and not quick:
        large_study(k_large, smoothing, repeats)
    return rows


def large_study(k_large, smoothing, repeats=1):
    """The smoothed law with the preset solver in natural variables at `k_large`,
    no reference: slack_snap_k<k_large>.{md,csv}."""
    from _common import write_table

    large = []
    for case in CASES:
        for f in ("natural", "angle"):
            r = run(f, case, k_large, smoothing, SOLVERS[f][0], repeats=repeats)
            large.append(_row(case, f, k_large, "smooth", SOLVERS[f][0], r, None))
            print(_line(large[-1]), flush=True)
    title = (
        "Slack and snap: the smoothed tension-only law "
        f"(eps_s = {smoothing:g}), rtol = atol = {TOL:g}, t1 = {T1:g} s"
    )
    notes = [
        "steps, rejected: accepted and rejected steps.",
        f"run_s, cpu_s: the least of up to {repeats} full runs after compilation "
        f"(wall, process CPU), s; one run where it took over {REPEAT_BUDGET_S:g} s.",
    ]
    write_table(f"slack_snap_k{k_large}", large, COLUMNS, title, notes=notes)
    return large


# Gradient study: (k, EA, t1) of the snap case (released from 3 pi/4, (eps, phi)).
GRADIENT_CASES = ((4, 1e6, 0.6), (4, 1e6, 2.0))
# (adjoint, solver, rtol) per case.
GRADIENT_METHODS = (
    ("forward", "rodas5p", 1e-9),
    ("forward", "rodas5p", 1e-11),
    ("forward", "kvaerno5", 1e-8),
    ("forward", "kvaerno5", 1e-9),
    ("sensitivity", "rodas5p", 1e-9),
    ("sensitivity", "kvaerno5", 1e-9),
)
FD_TOL = 1e-11
FD_STEPS = (1e-4, 1e-5)


def _end_loss(traj, sc):
    """x + y / 2 of the end mass at the last save time (m)."""
    del sc
    return jnp.sum(traj.obs["positions"][-1, -1, :] * jnp.array([1.0, 0.5]))


GETTERS = (("alpha", lambda s: s.effects[1].alpha), ("EA", lambda s: s.model.EA))


def central_differences(sc, n_save, rel_step):
    """d loss / d(alpha, EA) by central differences of Rodas5P solves at FD_TOL."""
    import equinox as eqx

    from jaxstring import _fit

    config = _fit.SolveConfig(
        solver="rodas5p", rtol=FD_TOL, atol=FD_TOL, n_save=n_save, max_steps=4_000_000
    )
    f = eqx.filter_jit(lambda s: _end_loss(_fit.solve(s, config), s))
    out = {}
    for name, get in GETTERS:
        p = float(get(sc))
        h = rel_step * p
        plus = float(f(eqx.tree_at(get, sc, jnp.asarray(p + h))))
        minus = float(f(eqx.tree_at(get, sc, jnp.asarray(p - h))))
        out[name] = (plus - minus) / (2 * h)
    return out


def gradient_study(quick=False):
    """The end-mass position after a snap, differentiated in forward mode and with
    error-controlled sensitivities, against central differences:
    slack_snap_gradients.{md,csv}."""
    from _common import write_table

    import jaxstring as js

    cases = GRADIENT_CASES[:1] if quick else GRADIENT_CASES
    rows = []
    for k, EA, t1 in cases:
        sc = js.string_pendulum(
            formulation="angle",
            k=k,
            EA=EA,
            alpha=0.01,
            theta0=3 * math.pi / 4,
            t1=t1,
            effects=("gravity", "kelvin_voigt", "slack"),
        )
        n_save = int(round(t1 * 100)) + 1
        fd = {h: central_differences(sc, n_save, h) for h in FD_STEPS}
        ref = fd[FD_STEPS[-1]]
        spread = {
            n: abs(fd[FD_STEPS[0]][n] - ref[n]) / abs(ref[n]) for n in ("alpha", "EA")
        }
        for adjoint, solver, rtol in GRADIENT_METHODS:
            row = dict(k=k, EA=EA, t1=t1, adjoint=adjoint, solver=solver, rtol=rtol)
            names = ("adjoint", "solver", "rtol", "atol")
            kw = dict(zip(names, (adjoint, solver, rtol, rtol)), n_save=n_save)
            kw["max_steps"] = 1_000_000
            call = lambda kw=kw: js.value_and_grad(sc, _end_loss, ["alpha", "EA"], **kw)
            try:
                _, first, _ = clock(call)
                (_, grad), row["run_s"], _ = clock(call)
                row["compile_s"] = max(first - row["run_s"], 0.0)
                row["ok"] = True
            except Exception as e:  # noqa: BLE001 (a failure is a result)
                row.update(ok=False, status=f"{type(e).__name__}"[:60])
                rows.append(row)
                print(row, flush=True)
                continue
            for n in ("alpha", "EA"):
                row[f"d_{n}"] = float(grad[n])
                row[f"fd_{n}"] = ref[n]
                row[f"err_{n}"] = abs(float(grad[n]) - ref[n]) / abs(ref[n])
                row[f"fd_spread_{n}"] = spread[n]
            row["status"] = "success" if np.isfinite(row["d_alpha"]) else "non-finite"
            rows.append(row)
            print(row, flush=True)
    columns = (
        "k EA t1 adjoint solver rtol ok d_alpha d_EA err_alpha err_EA fd_alpha "
        "fd_EA fd_spread_alpha fd_spread_EA compile_s run_s status"
    ).split()
    write_table(
        "slack_snap_gradients",
        rows,
        columns,
        "Gradients through snaps: d(x + y/2 of the end mass at t1)/d(alpha, EA), "
        "(eps, phi), released from 3 pi/4, smoothed law "
        f"(eps_s = {SLACK_SMOOTHING['angle']:g})",
        notes=[
            "adjoint: forward = diffrax's ForwardMode through the solve (the "
            "derivative along the state's steps); sensitivity = the sensitivities "
            "integrated beside the state under the error control "
            "(jaxstring._sensitivity).",
            f"fd_*: central differences of Rodas5P solves at rtol = atol = {FD_TOL:g},"
            f" steps of {FD_STEPS[-1]:g} of the value; err_*: |d - fd| / |fd|; "
            f"fd_spread_*: the same central differences with steps of "
            f"{FD_STEPS[0]:g} against them.",
            "run_s: the second call of value_and_grad (wall, s); compile_s: the first "
            "minus the second. A failed call shows its exception.",
        ],
    )
    return rows


def _error(end, ref):
    from _common import end_mass_error

    if end is None or ref is None:
        return float("nan")
    return end_mass_error(end, ref)


def _line(r):
    return (
        f"{r['case']:7s} {r['formulation']:12s} k={r['k']:4d} {r['law']:6s} "
        f"{r['solver']:12s} {r['status'][:12]:12s} steps={r['steps']} "
        f"rej={r['rejected']} run={r['run_s']:.2f}s cpu={r['cpu_s']:.2f}s "
        f"compile={r['compile_s']:.1f}s err={r['error_m']:.2e}"
    )


def smoothing_table(smoothing, k=10):
    """The change of the answer with eps_s: tight solves (Rodas5P, rtol 1e-9) at
    eps_s = 100, 10, 1, 0.1 x the default, against eps_s = 1e-9, in (eps, phi)
    variables at k = 10 (the displacement variables' tight solves do not complete
    in minutes)."""
    from _common import write_table

    rows = []
    for case in CASES:
        for f in ("angle",):
            ref = reference(f, case, k, rtol=1e-9)
            for factor in (100.0, 10.0, 1.0, 0.1):
                eps_s = smoothing * factor
                end = reference(f, case, k, smoothing=eps_s, rtol=1e-9)
                EA = CASES[case]["EA"]
                rows.append(
                    dict(
                        case=case,
                        formulation=f,
                        k=k,
                        eps_s=eps_s,
                        force_N=EA * eps_s,
                        change_m=_error(end, ref),
                    )
                )
    write_table(
        "slack_snap_smoothing",
        rows,
        ["case", "formulation", "k", "eps_s", "force_N", "change_m"],
        f"Change of the end-mass trajectory with the transition strain eps_s "
        f"(Rodas5P, rtol = atol = 1e-9, against eps_s = {REF_SMOOTHING:g})",
        notes=[
            "force_N: EA eps_s, the force scale of the blend (the elastic force "
            "differs from the sharp law's by at most 0.317 EA eps_s)."
        ],
    )
    return rows


STEP_HEADER = (
    "formulation,solver,law,t_from_s,accepted_steps,h_min_s,h_median_s,state_changes"
)


def step_windows(label, ts, h, changes, width=0.01):
    """The per-step log in windows of `width` s: accepted steps, smallest and
    median step, and changes of state (taut/slack) of the tension points."""
    out = []
    for a in np.arange(0.0, T1, width):
        m = (ts > a) & (ts <= a + width)
        if m.any():
            out.append(
                f"{label},{a:.3f},{int(m.sum())},{h[m].min():.3g},"
                f"{np.median(h[m]):.3g},{int(changes[m].sum())}"
            )
    return out


def step_figure(smoothing, k):
    """Step size over time, sharp (before) and smoothed (after), EA = 1e8 snap, in
    each formulation with its preset solver; the per-step log, in 10 ms windows,
    in slack_snap_steps.csv."""
    from _common import new_figure, savefig, write_text

    fig, axes = new_figure(ncols=3, w=4.6, h=3.6)
    lines = [STEP_HEADER]
    for ax, f in zip(axes[0], FORMULATIONS):
        solver = SOLVERS[f][0]
        for law, eps_s, color in (("sharp", 0.0, "0.6"), ("smooth", smoothing, "C0")):
            ts, h, ch = step_log(f, "snap", k, eps_s, solver)
            ax.semilogy(ts, h, ".", ms=1.5, color=color, label=f"{law} ({len(ts)})")
            lines += step_windows(f"{f},{solver},{law}", ts, h, ch)
        ax.set_title(f"{f}, {solver}, k = {k}")
        ax.set_xlabel("t (s)")
        ax.set_xlim(0, T1)
        ax.legend(loc="lower right", fontsize=7, markerscale=6)
    axes[0][0].set_ylabel("accepted step size (s)")
    fig.suptitle(
        f"EA = 1e8, released from 3 pi/4: sharp vs eps_s = {smoothing:g} "
        "(accepted steps in the legend)",
        fontsize=9,
    )
    savefig(fig, "slack_snap")
    write_text("slack_snap_steps.csv", "\n".join(lines) + "\n")


if __name__ == "__main__":
    from _common import run_study

    run_study(
        main,
        k=dict(type=int, default=None, help="elements (default 40; quick 10)"),
        k_large=dict(type=int, default=None, help="also this k, smoothed law only"),
        smoothing=dict(type=float, default=None, help="eps_s (default 1e-7)"),
        large_only=dict(action="store_true", help="only the --k_large study"),
        gradients_only=dict(action="store_true", help="only the gradient study"),
    )
