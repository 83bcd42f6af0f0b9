"""Fig 10 of Poth et al.: wall time vs EA for every integrator at the paper's settings.

Question: how does each integrator's cost grow with the stiffness EA, at the
paper's settings (k = 40, 2 s; fixed-step methods dt = 0.005 s = 400 steps;
adaptive ones rtol = atol = 1e-7; Newton tolerance 1e-7)? Every jaxstring solver
in ``jaxstring.SOLVERS`` runs (new ones appear automatically), next to the strongest
peers: CVODE BDF with the band linear solver on an independent numba implementation
of the same equations (jaxstring/testing/peers.py), and scipy's Radau, BDF and LSODA
on the same compiled functions; CVODE driving jaxstring's JAX functions through Python
callbacks is a labelled second row (``--no_callback`` leaves it out). Each row has
the end-mass error against CVODE-numba at rtol = atol = 1e-11, and a second table
says where jaxstring's implicit time goes (Jacobians, LU, Newton).

Run: ``python experiments/fig10_integrators.py [--quick]``.
"""

import math
import statistics

import _common as common
import harness
import jax
import jax.numpy as jnp
import numpy as np

import jaxstring
from jaxstring.testing import references


CVODE = "CVODE-numba"
CALLBACK = "CVODE on JAX callbacks"
PAPER = {"k": 40, "t1": 2.0, "dt": 0.005, "tol": 1e-7, "newton_tol": 1e-7}
EAS = (1e4, 1e5, 1e6, 1e7, 1e8, 1e9)
# Implicit stages per step (the ESDIRKs' first stage is explicit).
IMPLICIT_STAGES = {
    "kvaerno3": 3,
    "kvaerno4": 4,
    "kvaerno5": 6,
    "implicit_euler": 1,
    "implicit_euler_fixed": 1,
}


REF_TOL = harness.REF_TOL
# The columns of this study's tables that have other names in a harness record.
NAMES = {"code": "solver", "wall_s": "run_s", "accepted": "steps"}


def peer_reference(case, peer, ts, tol=REF_TOL):
    """End mass from CVODE-numba at rtol = atol = `tol`, and its label."""
    return harness.reference(case, ts, "cvode-numba", tol, peer=peer)


def peer_codes(scene, peer, y0, ts, budget_s, callback=True):
    """The peers on one scene: CVODE-numba, scipy's Radau, BDF and LSODA on the
    same numba functions, and CVODE on jaxstring's JAX functions through Python
    callbacks (the labelled second row)."""
    tag = "analytic band Jacobian" if peer.jac is not None else "band DQ Jacobian"
    codes = [harness.cvode_numba_code(peer, ts, y0)]
    for method in ("Radau", "BDF", "LSODA"):
        codes.append(harness.scipy_numba_code(
            peer, method, ts, y0, label=f"scipy-{method} numba [{tag}]",
            cpu_limit_s=budget_s,
        ))  # fmt: skip
    for code in codes:
        code.kind = "strong"
    if callback and references.available()["cvode-BDF"]:
        codes.append(harness.callback_code(
            scene, "cvode-BDF", ts, label=f"{CALLBACK} [band Jacobian]"
        ))  # fmt: skip
    return codes


def _factorisations_per_attempt(name, scene):
    """The fewest Jacobians (each factorised once) in an attempted step of `name`:
    full Newton (the fixed-step implicit Euler) takes one per iteration, two at
    least; Kvaerno one per implicit stage where the model asks for it
    (`stage_jacobians`: displacement variables), else one per step, shared by the
    stages (their diagonal coefficient is the same). Refreshes on slow
    contraction come on top."""
    if name == "implicit_euler_fixed":
        return 2
    if name.startswith("kvaerno") and scene.structure.stage_jacobians:
        return IMPLICIT_STAGES[name]
    return 1


def _loop_time(fn, x, reps):
    """Median per-call time (us) of `fn(x)` inside one compiled loop."""

    def body(c, _):
        out = fn(x.at[0].add(1e-30 * c))
        # reduce the whole output, so that no part of `fn` is dead code
        return c + 1e-30 * jnp.sum(jax.tree_util.tree_leaves(out)[0])

    return harness.in_loop_us(body, jnp.zeros(()), n=reps, stat=statistics.median)


def where_time_goes(scene, rows_js, peer_rows, quick=False):
    """Cost of the pieces of an implicit step, measured inside jit on the linear
    algebra the solvers choose for this scene ("auto": a block-tridiagonal Jacobian
    from coloured JVPs and block cyclic reduction, or a dense Jacobian and LU), and
    the counts."""
    from jaxstring import _linalg

    y0 = jnp.asarray(scene.y0)
    shape = y0.shape
    vf = lambda u, s: s.vector_field(0.0, u)
    width = _linalg.choose_structure(vf, y0, scene, "auto")
    f = lambda y: scene.vector_field(0.0, y.reshape(shape)).reshape(-1)
    jac = lambda y: _linalg.jacobian(lambda u: vf(u, scene), y.reshape(shape), width)
    J = jac(y0.reshape(-1))
    fac = lambda m: _linalg.factor(J.scale_shift(1.0, -1e-3 * (1.0 + m[0])))
    F = fac(jnp.zeros(1))
    reps = 20 if quick else 200
    leaf = lambda tree: jax.tree_util.tree_leaves(tree)[0]
    cost = {
        "f_us": _loop_time(f, y0.reshape(-1), reps),
        "jac_us": _loop_time(lambda y: leaf(jac(y)), y0.reshape(-1), reps),
        "lu_us": _loop_time(lambda m: leaf(fac(m)), jnp.zeros(1), reps),
        "solve_us": _loop_time(
            lambda b: F.solve(b.reshape(shape)), y0.reshape(-1), reps
        ),
    }
    path = "dense LU" if width is None else f"block-tridiagonal, {width} node(s)/block"
    out = []
    for r in rows_js:
        if not r.get("ok") or r["solver"] not in IMPLICIT_STAGES:
            continue
        stages = IMPLICIT_STAGES[r["solver"]]
        nj = _factorisations_per_attempt(r["solver"], scene)
        attempts = r["num_steps"]
        per_attempt_us = 1e6 * r["run_s"] / max(attempts, 1)
        # The least arithmetic of an attempt: its Jacobians and factorisations, and
        # two Newton iterations (f + back-substitution) per implicit stage, the
        # fewest before the convergence-rate test can pass.
        floor_us = nj * (cost["jac_us"] + cost["lu_us"]) + 2 * stages * (
            cost["f_us"] + cost["solve_us"]
        )
        out.append(
            {
                "EA": r["EA"],
                "solver": r["solver"],
                "attempts": attempts,
                "rejected": r["num_rejected_steps"],
                "factorisations": nj * attempts,
                "us_per_attempt": per_attempt_us,
                "floor_us_per_attempt": floor_us,
                "over_floor": per_attempt_us / floor_us,
                "floor_s": floor_us * attempts * 1e-6,
                "run_s": r["run_s"],
            }
        )
    for r in peer_rows:
        if r.get("ok") and r["solver"].startswith((CVODE, "scipy-Radau")):
            out.append(
                {
                    "EA": r["EA"],
                    "solver": r["solver"],
                    "attempts": "-",
                    "rejected": "-",
                    "factorisations": r["njev"],
                    "run_s": r["run_s"],
                    "nfev": r["nfev"],
                }
            )
    return cost, out, path


def _skipped(EA, name):
    return {
        "EA": EA,
        "solver": name,
        "ok": False,
        "status": "skipped (failed or over budget at lower EA)",
    }


def _keep(r, tables, dead, budget_s):
    """Add a finished row to `tables`; a code that failed or ran past the budget
    sits out the stiffer EAs (`dead`)."""
    if not r["ok"] or r["run_s"] > budget_s:
        dead.add(r["solver"])
    for table in tables:
        table.append(r)
    print(f"EA={r['EA']:g} {r['solver']}: {r['run_s']:.3g} s ok={r['ok']}", flush=True)


def main(
    quick=False,
    formulation="angle",
    EAs=None,
    solvers=None,
    repeats=None,
    budget_s=60.0,
    no_callback=False,
):
    """Run the Fig 10 study; return the result rows."""
    common.set_quick(quick)
    k = 8 if quick else PAPER["k"]
    t1 = 0.2 if quick else PAPER["t1"]
    EAs = EAs or ((1e4, 1e6) if quick else EAS)
    repeats = repeats or (1 if quick else 3)
    names = solvers or common.solver_names(
        "all", ["kvaerno5", "implicit_euler_fixed"] if quick else None
    )
    names = [n for n in names if n in jaxstring.SOLVERS]
    ts = np.linspace(0.0, t1, 41)
    rows, js_rows, peer_rows = [], [], []
    dead = set()  # configurations that failed or ran past the budget: skip higher EA
    last_scene = None
    for EA in EAs:
        case = harness.PendulumCase(formulation, EA=EA, k=k, t1=t1)
        scene, peer = case.scene(), case.peer()
        last_scene = scene
        y0 = np.ravel(np.asarray(scene.y0, dtype=np.float64))
        peer.warmup()
        ref, ref_label = peer_reference(case, peer, ts)
        for name in names:
            if name in dead:
                rows.append(_skipped(EA, name))
                continue
            kw = dict(newton_rtol=PAPER["newton_tol"], newton_atol=PAPER["newton_tol"])
            if not jaxstring.SOLVERS[name][1]:
                kw["dt0"] = PAPER["dt"]  # fixed step
            code = harness.jaxstring_code(scene, name, ts, **kw)
            # a first call (compile), then the median of `repeats`
            rec = harness.repeat(code, PAPER["tol"], repeats)
            (r,) = harness.rows(harness.score([rec], ref), NAMES)
            r.update(EA=EA)
            _keep(r, (rows, js_rows), dead, budget_s)
        for code in peer_codes(scene, peer, y0, ts, budget_s, not no_callback):
            if code.label in dead:
                rows.append(_skipped(EA, code.label))
                continue
            # the warm-up (numba's compile, JAX's jit) apart, then the median
            rec = harness.repeat(code, PAPER["tol"], repeats, first=False)
            (r,) = harness.rows(harness.score([rec], ref), NAMES)
            r.update(EA=EA)
            _keep(r, (rows, peer_rows), dead, budget_s)
    # Normalise like the paper: 1 = the fastest successful run at the smallest EA.
    base = min(
        (r["run_s"] for r in rows if r.get("ok") and r["EA"] == EAs[0]),
        default=math.nan,
    )
    cvode = {r["EA"]: r["run_s"] for r in peer_rows if r["solver"].startswith(CVODE)}
    for r in rows:
        r["cpu_rel"] = r["run_s"] / base if r.get("ok") else math.nan
        ok = r.get("ok")
        r["x_cvode"] = r["run_s"] / cvode.get(r["EA"], math.nan) if ok else math.nan
    tag = "_quick" if quick else ""
    cols = (
        "EA solver ok run_s repeats compile_s cpu_rel x_cvode err_m num_steps "
        "num_rejected_steps nfev njev status"
    ).split()
    common.write_table(
        f"fig10_integrators{tag}",
        rows,
        cols,
        f"Fig 10: wall time vs EA, formulation {formulation}, k={k}, t1={t1} s, "
        f"fixed dt={PAPER['dt']}, rtol=atol=newton tol={PAPER['tol']:g}",
        notes=[
            "run_s: median wall time (s) of `repeats` runs after a first call; "
            "compile_s: jaxstring's first call minus the median, the peers' numba "
            "compile or cache load and JAX jit of the callback functions.",
            "cpu_rel: run_s / fastest successful run at the smallest EA (the paper's "
            f"normalisation); x_cvode: run_s / {CVODE}'s at the same EA (< 1: faster).",
            f"err_m: max end-mass distance over {len(ts)} save times from {ref_label}"
            " (same variables).",
            f"{CVODE}: CVODE BDF (scikit-sundae), band linear solver, on the numba "
            "right-hand side of jaxstring/testing/peers.py (checked against "
            "jaxstring's vector field in tests/test_peers.py); scipy-* numba: "
            "solve_ivp on the same compiled function with the same Jacobian option; "
            "analytic band Jacobian where the peer has one (displacement), else "
            f"banded difference quotients. {CALLBACK}: CVODE driving jaxstring's own "
            "JAX functions through Python callbacks, JAX band Jacobian (a second row, "
            "for scale).",
        ],
    )
    # Where the time goes (at the stiffest EA that ran).
    cost, diag, path = where_time_goes(
        last_scene,
        [r for r in js_rows if r["EA"] == EAs[-1]],
        [r for r in peer_rows if r["EA"] == EAs[-1]],
        quick,
    )
    common.write_table(
        f"fig10_where_time_goes{tag}",
        diag,
        [
            "EA",
            "solver",
            "attempts",
            "rejected",
            "factorisations",
            "nfev",
            "us_per_attempt",
            "floor_us_per_attempt",
            "over_floor",
            "floor_s",
            "run_s",
        ],
        f"Where jaxstring's implicit time goes ({formulation}, k={k}, "
        f"n={last_scene.y0.size} states, EA={EAs[-1]:g})",
        notes=[
            f"linear algebra of the solvers' 'auto' path here: {path}; "
            "cost of the pieces inside jit (us): "
            + ", ".join(f"{key} {v:.1f}" for key, v in cost.items()),
            "factorisations: Jacobians built and factorised, the fewest the method "
            "takes (jaxstring: Kvaerno one per implicit stage in displacement "
            "variables, one per step shared by the stages in natural variables; "
            "full Newton two per fixed step; refreshes on slow contraction not "
            "counted); CVODE: its Jacobian evaluations (njev), each reused over "
            "many steps.",
            "floor_us_per_attempt: factorisations per attempt x (Jacobian + "
            "factorisation) + 2 Newton iterations x implicit stages x (f + solve), "
            "the pieces timed above; over_floor: measured time per attempt / floor; "
            "floor_s: the floor times the attempts, the least run time of the same "
            "steps with no other cost.",
        ],
    )
    _plot(rows, EAs, formulation, k, tag)
    return rows


def _plot(rows, EAs, formulation, k, tag):
    fig, axes = common.new_figure(2, 1, w=5.5)
    ax, ax2 = axes[0]
    names = list(dict.fromkeys(r["solver"] for r in rows))
    for name in names:
        pts = [
            (r["EA"], r["cpu_rel"], r.get("err_m"))
            for r in rows
            if r["solver"] == name and r.get("ok")
        ]
        if not pts:
            continue
        style = "--" if "[" in name else "-"
        x, y, e = zip(*pts)
        ax.loglog(x, y, style, marker="o", ms=3, label=name)
        ax2.loglog(x, e, style, marker="o", ms=3, label=name)
    ax.set_xlabel("EA (N)")
    ax.set_ylabel("wall time (1 = fastest at smallest EA)")
    ax.set_title(f"Fig 10: integrators, {formulation}, k={k}")
    ax2.set_xlabel("EA (N)")
    ax2.set_ylabel("end-mass error vs tight reference (m)")
    ax2.set_title("accuracy of the same runs")
    ax.legend(fontsize=6, ncol=2)
    common.savefig(fig, f"fig10_integrators{tag}")


if __name__ == "__main__":
    common.run_study(
        main,
        lists={"EAs": float, "solvers": str},
        formulation=dict(help="string formulation"),
        budget_s=dict(help="a code past this many seconds sits out the stiffer EAs"),
        no_callback=dict(action="store_true", help="leave out the callback row"),
    )
