"""Fast stiff integration: jaxstring's implicit solvers against CVODE.

Question: on the string pendulum in displacement variables (k = 40, alpha = 0.01,
2 s, rtol = atol = 1e-6), how fast are jaxstring's solvers after compilation, at
what end-mass error, and how does the best one scale with the number of elements?

* Table 1, per solver x EA in {1e4, 1e6, 1e9}: wall time after compile (median of
  repeats), compile time, steps (rejected), end-mass error (max over 201 save times)
  against a tight reference (Rodas5P, rtol = atol = 1e-10), and the ratio to CVODE
  (scikit-sundae, BDF, band solver, the JAX-compiled RHS and its banded JAX
  Jacobian through callbacks) measured in the same run, if installed.
* Table 2: wall time vs k at EA = 1e6 (k = 40 ... 1280) for Rodas5P (and CVODE up
  to k = 320), with the fitted exponent.
* Table 3, where the time goes: the cost of one vector field, one banded Jacobian
  (3 b coloured JVPs), one block-cyclic-reduction factorisation and one solve,
  measured inside a compiled loop, against the dense jacfwd + LU path.

Writes experiments/results/bench_solvers.{md,csv,png}.
Run: ``python experiments/bench_solvers.py [--quick]`` (quick: k = 10, 0.5 s, EA in
{1e4, 1e6}, k = 10 ... 40; a smoke test, about a minute).
"""

import argparse
import importlib.util
import os

import _common as common
import diffrax as dfx
import harness
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np

import jaxstring as js
from jaxstring import _linalg
from jaxstring._solvers.stage_newton import StageNewton


ADAPTIVE = (
    "rodas5p",
    "bdf",
    "kvaerno3",
    "kvaerno5",
    "kvaerno5-pid",
    "kvaerno5-newton",
    "kvaerno5-stepjac",
    "implicit_euler",
)
FIXED = ("theta", "newmark", "implicit_euler_fixed")


def _solver(name, rtol, atol):
    """A name simulate knows, or a variant built here."""
    if name.endswith("-pid"):
        return name[: -len("-pid")]
    if name == "kvaerno5-newton":
        rf = StageNewton(rtol=rtol, atol=atol, max_iters=10, newton=True)
        return js.Kvaerno5(root_finder=rf, root_find_max_steps=10)
    if name == "kvaerno5-stepjac":
        # diffrax's own Kvaerno5: one Jacobian per step (second stage's predictor)
        rf = StageNewton(rtol=rtol, atol=atol, max_iters=10)
        return dfx.Kvaerno5(root_finder=rf, root_find_max_steps=10)
    return name


# The columns of this study's tables that have other names in a harness record.
NAMES = {"code": "solver", "wall_s": "run_s", "accepted": "steps"}


def solver_code(scene, name, ts, rtol, atol, max_steps=400_000):
    """Solver `name` (or a variant built here) on `scene`; fixed-step solvers at
    dt = 0.005 s; "-pid": diffrax's plain PIDController (before
    NewtonLimitedController)."""
    kw = {"step_control": "pid"} if name.endswith("-pid") else {}
    solver = _solver(name, rtol, atol)
    if isinstance(solver, str) and not js.SOLVERS[solver][1]:
        kw["dt0"] = 0.005
    return harness.jaxstring_code(
        scene, solver, ts, label=name, max_steps=max_steps, **kw
    )


def cvode_code(scene, ts):
    """CVODE BDF (band solver) on the scene's JAX functions through callbacks."""
    return harness.callback_code(
        scene, "cvode-BDF", ts, label="CVODE BDF (band, JAX Jacobian)"
    )


def run_solver(scene, name, ts, rtol, atol, repeats, max_steps=400_000):
    """One solver's row: a first call (compile), then the median of `repeats`."""
    code = solver_code(scene, name, ts, rtol, atol, max_steps)
    return harness.rows([harness.repeat(code, rtol, repeats)], NAMES, drop=())[0]


def run_cvode(scene, ts, rtol, atol, repeats):
    """CVODE's row: the callbacks' JIT compile apart, then the median of
    `repeats` (no steps reported)."""
    r = harness.repeat(cvode_code(scene, ts), rtol, repeats, first=False)
    r["status"] = r["message"][:60]  # CVODE's own words
    return harness.rows([r], NAMES, drop=())[0]


def solver_block(EA, k, t1, names, rtol, atol, repeats, extra=None):
    """The default pendulum (displacement variables) at `EA`: CVODE (when
    installed) and each solver of `names` at one tolerance, plus `extra(scene, ts)`
    rows; returns (rows, the tight reference's end-mass path)."""
    case = harness.PendulumCase("displacement", EA=EA, k=k, t1=t1)
    scene = case.scene()
    ts = jnp.linspace(0.0, t1, 201)
    ref_end = harness.reference(
        scene, ts, "rodas5p", 1e-10, max_steps=4_000_000, verbose=True
    )[0]
    rows = []
    if importlib.util.find_spec("sksundae") is not None:
        rows.append(run_cvode(scene, ts, rtol, atol, repeats))
    rows += [run_solver(scene, name, ts, rtol, atol, repeats) for name in names]
    if extra is not None:
        rows.append(extra(scene, ts))
    return rows, ref_end


def component_costs(k, EA=1e6, reps=200):
    """In-loop cost (us) of the pieces of an implicit step at k elements."""
    scene = js.string_pendulum("displacement", k=k, EA=EA, theta0=1.0)
    y = scene.y0 + 1e-3 * jax.random.normal(jax.random.PRNGKey(0), scene.y0.shape)
    fn = lambda u: scene.vector_field(0.0, u)
    n, b = y.shape
    dense_fn = lambda v: fn(v.reshape(n, b)).reshape(-1)
    bt = _linalg.block_tridiagonal_jacobian(fn, y, 1).scale_shift(1.0, -1e-4)
    F = _linalg.bcr_factor(bt)
    Y = y.reshape(bt.diag.shape[0], -1)
    Jd = jnp.eye(n * b) - 1e-4 * jax.jacfwd(dense_fn)(y.reshape(-1))
    LU = jsl.lu_factor(Jd)

    def loop(body, x0):
        return harness.in_loop_us(lambda x, _: body(x), x0, n=reps, stat=min)

    def new_diag(d):
        m = _linalg.BlockTridiagonal(bt.lower, d, bt.upper, bt.n, bt.b, 1)
        return d + 1e-12 * _linalg.bcr_factor(m).dinv_last.sum()

    return {
        "k": k,
        "vector field": loop(lambda u: u + 1e-12 * fn(u), y),
        "banded Jacobian (3b JVPs)": loop(
            lambda u: (
                u + 1e-12 * _linalg.block_tridiagonal_jacobian(fn, u, 1).diag.sum()
            ),
            y,
        ),
        "dense Jacobian (jacfwd)": loop(
            lambda u: u + 1e-12 * jax.jacfwd(dense_fn)(u.reshape(-1)).sum(), y
        ),
        "BCR factor": loop(new_diag, bt.diag),
        "dense LU factor": loop(lambda m: m + 1e-12 * jsl.lu_factor(m)[0].sum(), Jd),
        "BCR solve": loop(lambda f: _linalg.bcr_solve(F, f), Y),
        "dense LU solve": loop(lambda f: jsl.lu_solve(LU, f), y.reshape(-1)),
    }


def main(
    quick=False,
    solvers=None,
    repeats=3,
    suffix="",
    scaling=True,
    kmax=None,
    table1=True,
):
    common.set_quick(quick)
    tag = ("_quick" if quick else "") + suffix
    k = 10 if quick else 40
    t1 = 0.5 if quick else 2.0
    EAs = (1e4, 1e6) if quick else (1e4, 1e6, 1e9)
    ks = (10, 20, 40) if quick else (40, 80, 160, 320, 640, 1280)
    ks = tuple(kk for kk in ks if kmax is None or kk <= kmax)
    cvode_kmax = 40 if quick else 320
    rtol = atol = 1e-6
    have_cvode = importlib.util.find_spec("sksundae") is not None
    names = solvers or (ADAPTIVE + FIXED)
    print(f"CVODE (scikit-sundae): {'yes' if have_cvode else 'not installed'}")

    rows = []
    for EA in EAs if table1 else ():
        block_rows, ref_end = solver_block(EA, k, t1, names, rtol, atol, repeats)
        common.score_rows(
            block_rows, ref_end, block_rows[0] if have_cvode else None, EA=EA
        )
        rows.extend(block_rows)
    cols = (
        "EA solver ok run_s compile_s repeats steps rejected us_per_attempt "
        "error_m vs_cvode status"
    ).split()
    notes = [
        f"String pendulum, displacement variables, k = {k}, alpha = 0.01, "
        f"{t1} s, rtol = atol = 1e-6; fixed-step solvers at dt = 0.005 s.",
        "error_m: max over 201 save times of the end-mass distance to Rodas5P at "
        "rtol = atol = 1e-10. run_s: median after compile; vs_cvode: ratio measured "
        "in the same run.",
        "kvaerno5-stepjac: diffrax's Kvaerno5 (one Jacobian per step, at the "
        "second stage's predictor; jaxstring's takes one at every stage's predictor)",
        "kvaerno5-newton: Kvaerno5 with StageNewton(newton=True) (fresh banded "
        "Jacobian at every iteration).",
        "NAME-pid: the solver with diffrax's plain PIDController "
        "(`step_control='pid'`); without the suffix the Kvaerno/implicit-Euler "
        "solvers use NewtonLimitedController (jaxstring/_solvers/step_size.py).",
    ]
    if not have_cvode:
        notes.append("CVODE not measured: scikit-sundae is not installed here.")
    if table1:
        common.write_table(
            f"bench_solvers{tag}",
            rows,
            cols,
            "Solvers on the stiff string pendulum",
            notes,
        )

    if not scaling:
        return rows, None, None
    # Scaling in k at EA = 1e6 (Rodas5P, CVODE).
    scal = []
    for kk in ks:
        scene = js.string_pendulum("displacement", k=kk, EA=1e6, t1=t1)
        ts = jnp.linspace(0.0, t1, 21)
        r = run_solver(scene, "rodas5p", ts, rtol, atol, 1 if kk > 160 else repeats)
        r.update(k=kk)
        scal.append(r)
        print(
            f"  k={kk:5d} rodas5p run={common.fmt(r.get('run_s'))}s "
            f"steps={r.get('steps')}"
            f" rej={r.get('rejected')}",
            flush=True,
        )
        if have_cvode and kk <= cvode_kmax:
            c = run_cvode(scene, ts, rtol, atol, 1 if kk > 160 else repeats)
            c.update(k=kk)
            scal.append(c)
            print(f"  k={kk:5d} CVODE   run={common.fmt(c.get('run_s'))}s", flush=True)
    fits = {}
    for label in {r["solver"] for r in scal}:
        pts = [(r["k"], r["run_s"]) for r in scal if r["solver"] == label and r["ok"]]
        if len(pts) >= 2:
            kk, tt = np.array(pts).T
            fits[label] = float(np.polyfit(np.log(kk), np.log(tt), 1)[0])
    for r in scal:
        r["exponent"] = fits.get(r["solver"])
    common.write_table(
        f"bench_solvers_scaling{tag}",
        scal,
        ["k", "solver", "ok", "run_s", "steps", "rejected", "exponent"],
        "Wall time vs number of elements k, EA = 1e6",
        [
            f"Fitted exponent of run_s ~ k^p over k = {ks[0]} ... {ks[-1]} "
            f"(CVODE up to {cvode_kmax}): "
            + ", ".join(f"{a}: {b:.2f}" for a, b in fits.items())
        ],
    )

    # Where the time goes.
    comp = [component_costs(kk) for kk in ((10, 40) if quick else (40, 160))]
    common.write_table(
        f"bench_solvers_components{tag}",
        comp,
        list(comp[0]),
        "In-loop cost of the pieces of an implicit step (us), EA = 1e6",
        ["Measured inside a compiled fori_loop (no dispatch overhead)."],
    )

    fig, ax = common.new_figure(2, 1, w=5.5)
    for name in {r["solver"] for r in rows}:
        pts = [
            (r["EA"], r["run_s"]) for r in rows if r["solver"] == name and r.get("ok")
        ]
        if pts:
            e, t = np.array(pts).T
            ax[0, 0].loglog(e, t, "o-", label=name)
    ax[0, 0].set_xlabel("EA (N)")
    ax[0, 0].set_ylabel("wall time after compile (s)")
    ax[0, 0].set_title(f"k = {k}, {t1} s, rtol = atol = 1e-6")
    if rows:
        ax[0, 0].legend(fontsize=6)
    for label, p in fits.items():
        pts = [(r["k"], r["run_s"]) for r in scal if r["solver"] == label and r["ok"]]
        kk, tt = np.array(pts).T
        ax[0, 1].loglog(kk, tt, "o-", label=f"{label} (k^{p:.2f})")
    ax[0, 1].set_xlabel("number of elements k")
    ax[0, 1].set_ylabel("wall time after compile (s)")
    ax[0, 1].set_title("EA = 1e6")
    ax[0, 1].legend(fontsize=7)
    common.savefig(fig, f"bench_solvers{tag}" + ("" if table1 else "_scaling"))
    return rows, scal, comp


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes (smoke test)")
    p.add_argument("--solvers", default=None, help="comma-separated solver names")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--suffix", default="", help="appended to the output names")
    p.add_argument("--no-scaling", action="store_true", help="table 1 only")
    p.add_argument(
        "--kmax", type=int, default=None, help="largest k of the scaling run"
    )
    p.add_argument(
        "--scaling-only", action="store_true", help="skip table 1 (solvers x EA)"
    )
    a = p.parse_args()
    main(
        quick=a.quick or bool(os.environ.get("SMOKE_TEST")),
        solvers=tuple(a.solvers.split(",")) if a.solvers else None,
        repeats=a.repeats,
        suffix=a.suffix,
        scaling=not a.no_scaling,
        kmax=a.kmax,
        table1=not a.scaling_only,
    )
