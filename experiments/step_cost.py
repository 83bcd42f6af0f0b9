"""Where the time of one BDF step goes as k grows (displacement string, EA = 1e6).

Question: a BDF step on the release start at k = 1280 costs about ten times one at
k = 40; which part of it grows? Each piece is timed *inside* one compiled loop (a
`lax.fori_loop` of `n` calls, so no dispatch cost is counted), as the solver runs
it: one vector field, the banded Jacobian by 12 coloured JVPs (the generic probe),
the model's own element-wise Jacobian (`DisplacementString.vf_jacobian`, which the
solvers use), the reduced factorisation of I - c J built from it,
one solve with it, and one whole `BDF.step` (repeated
from the same state: order 5, fresh Jacobian every step, as in displacement
variables). The last column is the cost
per step of a real `simulate` over a short release (rtol = atol = 1e-7). All in
microseconds, best of 5 loops, after compilation, one process.

Run: ``python experiments/step_cost.py [--quick]``.
"""

import argparse
import glob
import gzip
import json
import os
import tempfile

import diffrax as dfx
import equinox as eqx
import harness
import jax
import jax.numpy as jnp
import numpy as np
from _common import new_figure, savefig, set_quick, write_table  # sets XLA_FLAGS

import jaxstring
from jaxstring import _linalg
from jaxstring._scene import scene_vector_field
from jaxstring._solvers.bdf import BDF
from jaxstring.pendulum.effects import AbstractStringLoad, Loads


TIMES = (
    "rhs_us",
    "jacobian_us",
    "model_jacobian_us",
    "factor_us",
    "solve_us",
    "bdf_step_us",
    "simulate_step_us",
)

KERNEL_COLUMNS = tuple(
    f"{solver}_{col}"
    for solver in ("bdf", "kvaerno5")
    for col in ("kernels_per_step", "us_per_attempt", "ns_per_kernel")
)


def loop_us(body, x0, const, n):
    """Best of 5 of the mean time of one `body(x, const)` call in a compiled loop of
    `n` (`harness.in_loop_us`). `const` (the scene, the matrix, the factorisation)
    is an argument of the compiled function, not a constant folded into it, as in
    the solver."""
    return harness.in_loop_us(body, x0, const, n=n, rounds=5, stat=min)


def _touch(tree):
    """A scalar that depends on every array of `tree`, so that XLA computes all of
    it (a loop that used one block of a Jacobian would time a pruned Jacobian)."""
    return sum(jnp.sum(x) for x in jax.tree.leaves(eqx.filter(tree, eqx.is_array)))


def pieces(k, n):
    sc = jaxstring.string_pendulum(formulation="displacement", k=k, EA=1e6)
    y = sc.y0 + 0.01
    jac = lambda u, s: _linalg.jacobian(
        lambda v: s.vector_field(0.0, v), u, 1, second_order=2
    )
    # The solver's path: the model's own element-wise Jacobian (`vf_jacobian`).
    J = sc.model.vf_jacobian(0.0, y, sc.effects, sc.env)
    c = 1e-4
    F = _linalg.factor(J.scale_shift(1.0, -c))

    def fac_body(acc, JJ):
        Fc = _linalg.factor(JJ.scale_shift(1.0, -c * (1.0 + acc)))
        return acc + 1e-30 * _touch(Fc)

    row = {
        "k": k,
        "n_states": int(y.size),
        "rhs_us": loop_us(lambda u, s: u + 1e-9 * s.vector_field(0.0, u), y, sc, n),
        "jacobian_us": loop_us(lambda u, s: u + 1e-30 * _touch(jac(u, s)), y, sc, n),
        "model_jacobian_us": loop_us(
            lambda u, s: (
                u + 1e-30 * _touch(s.model.vf_jacobian(0.0, u, s.effects, s.env))
            ),
            y,
            sc,
            n,
        ),
        "factor_us": loop_us(fac_body, jnp.asarray(0.0), J, n),
        "solve_us": loop_us(lambda r, FF: 0.5 * (FF.solve(r) + r), y, F, n),
    }
    # One whole BDF step, repeated from the same (t0, y0) with the state carried.
    solver = BDF(rtol=1e-7, atol=1e-7, reuse_jacobian=False)
    term = dfx.ODETerm(scene_vector_field)
    h = 1e-4
    st0 = solver.init(term, 0.0, h, sc.y0, sc)
    step_body = lambda st, s: solver.step(term, 0.0, h, s.y0, s, st, False)[3]
    row["bdf_step_us"] = loop_us(step_body, st0, sc, n)
    return row


class ZeroLoad(AbstractStringLoad):
    """A load the string does not know and that adds nothing: under it the model
    gives no Jacobian of its own (`vf_jacobian` is None), so the solvers probe
    the vector field with 12 coloured JVPs."""

    def forces(self, t, kin, env):
        return Loads(jnp.zeros_like(kin.positions), jnp.zeros_like(kin.positions[-1]))


def simulate_per_step(k, t1):
    """Per-step wall time of a short release with the model's Jacobian and with
    the probed one (the same scene plus `ZeroLoad`), runs interleaved, best of 3."""
    sc = jaxstring.string_pendulum(formulation="displacement", k=k, EA=1e6, t1=t1)
    probed = eqx.tree_at(lambda s: s.effects, sc, sc.effects + (ZeroLoad(),))
    ts = np.linspace(0.0, t1, 5)
    runs = {
        name: lambda s=scene: jax.block_until_ready(
            jaxstring.simulate(s, "bdf", rtol=1e-7, atol=1e-7, ts=ts, max_steps=10**6)
        )
        for name, scene in (("model", sc), ("probed", probed))
    }
    for run in runs.values():
        run()
        run()  # the first execution can be slow without YNNPACK (README)
    best = {name: np.inf for name in runs}
    steps = {}
    for _ in range(3):
        for name, run in runs.items():
            traj, wall, _ = harness.clock(run)
            best[name] = min(best[name], wall)
            steps[name] = int(traj.stats["num_steps"])
    assert steps["model"] == steps["probed"], steps
    n = steps["model"]
    return best["model"] / n * 1e6, best["probed"] / n * 1e6, n


def _kernel_events(trace_dir):
    """Executed XLA kernels in a perfetto trace: one complete event per thunk run,
    less the executor's and JAX's own wrapper events."""
    path = glob.glob(os.path.join(trace_dir, "**", "*.trace.json.gz"), recursive=True)
    with gzip.open(path[0]) as f:
        events = json.load(f)["traceEvents"]
    wrappers = ("ThunkExecutor", "PjitFunction", "ExecuteHelper", "$", "while", "cond")
    return sum(
        1
        for e in events
        if e.get("ph") == "X" and not str(e.get("name", "")).startswith(wrappers)
    )


def kernels_per_step(k, t1, solver):
    """XLA kernels executed per step attempt of a short release (displacement,
    EA = 1e6, rtol = atol = 1e-7), counted in a profiler trace, and the wall time
    per attempt of the same run without the profiler (best of 3): their ratio is
    the mean cost of one kernel, launch included."""
    sc = jaxstring.string_pendulum(formulation="displacement", k=k, EA=1e6, t1=t1)
    ts = np.linspace(0.0, t1, 5)
    run = lambda: jax.block_until_ready(
        jaxstring.simulate(sc, solver, rtol=1e-7, atol=1e-7, ts=ts, max_steps=10**6)
    )
    run()
    best = np.inf
    for _ in range(3):
        traj, wall, _ = harness.clock(run)
        best = min(best, wall)
    attempts = int(traj.stats["num_steps"])
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d, create_perfetto_trace=True):
            run()
        n = _kernel_events(d)
    us = best / attempts * 1e6
    return n / attempts, us, us * 1e3 / (n / attempts)


def main(quick=False):
    set_quick(quick)
    ks = (40, 160) if quick else (40, 160, 640, 1280)
    n = 50 if quick else 200
    rows = []
    for k in ks:
        row = pieces(k, n)
        # a short release: about 1000-4000 steps at each k
        t1 = {40: 1.0, 160: 0.5, 640: 0.15, 1280: 0.1}[k]
        (
            row["simulate_step_us"],
            row["simulate_probed_step_us"],
            row["simulate_steps"],
        ) = simulate_per_step(k, t1)
        row["model_over_probed"] = (
            row["simulate_step_us"] / row["simulate_probed_step_us"]
        )
        row["simulate_t1"] = t1
        # a shorter span for the traces (a trace holds at most ~1M events)
        for solver in ("bdf", "kvaerno5"):
            (
                row[f"{solver}_kernels_per_step"],
                row[f"{solver}_us_per_attempt"],
                row[f"{solver}_ns_per_kernel"],
            ) = kernels_per_step(k, t1 / 5, solver)
        rows.append(row)
        print(
            f"k={k}: rhs {row['rhs_us']:.1f} jac {row['jacobian_us']:.1f} "
            f"model jac {row['model_jacobian_us']:.1f} "
            f"factor {row['factor_us']:.1f} solve {row['solve_us']:.1f} "
            f"step {row['bdf_step_us']:.0f} simulate/step "
            f"{row['simulate_step_us']:.0f} us (probed J "
            f"{row['simulate_probed_step_us']:.0f} us)",
            flush=True,
        )
    r0, r1 = rows[0], rows[-1]
    notes = [
        "Times in microseconds per call inside one compiled loop (best of 5), "
        "after compilation; simulate_step_us: wall time of a short simulate "
        "(release start, rtol = atol = 1e-7, t1 = simulate_t1 s) over its steps; "
        "simulate_probed_step_us: the same with the probed Jacobian (the scene plus "
        "a zero load the model does not know), runs interleaved in this process; "
        "model_over_probed: their ratio (same step counts, asserted).",
        "jacobian_us: the generic probe (12 coloured JVPs of the vector field); "
        "model_jacobian_us: the string's element-wise Jacobian, the one the solvers "
        "use; factor_us factorises I - c J from it.",
        "A displacement BDF step takes one Jacobian, one factorisation and about "
        "2-3 solves and vector fields; the rest of bdf_step_us is the step's own "
        "arithmetic on the difference array D (8 rows of the state) and the "
        "selects that carry the state.",
    ]
    notes.append(
        "*_kernels_per_step: XLA kernels (thunks) executed per step attempt, counted "
        "in a profiler trace of a release over simulate_t1 / 5 s (rtol = atol = "
        "1e-7), Newton iterations and rejected attempts included; *_us_per_attempt: "
        "wall time per attempt of the same run without the profiler (best of 3); "
        "*_ns_per_kernel: their ratio, the mean cost of one kernel with its launch. "
        "At small k a step is hundreds of kernels of a few hundred states each, and "
        "its time is their count times a launch-bound cost per kernel."
    )
    for col in TIMES:
        notes.append(
            f"{col}: k = {r1['k']} / k = {r0['k']}: {r1[col] / r0[col]:.1f}x "
            f"(k ratio {r1['k'] / r0['k']:.0f}; exponent "
            f"{np.log(r1[col] / r0[col]) / np.log(r1['k'] / r0['k']):.2f})."
        )
    name = "step_cost" + ("_quick" if quick else "")
    write_table(
        name,
        rows,
        [
            "k",
            "n_states",
            *TIMES,
            "simulate_probed_step_us",
            "model_over_probed",
            "simulate_steps",
            "simulate_t1",
            *KERNEL_COLUMNS,
        ],
        "Cost of one BDF step and its pieces vs k (displacement, EA = 1e6)",
        notes,
    )
    fig, axes = new_figure()
    ax = axes[0, 0]
    k = [r["k"] for r in rows]
    for col, lab in (
        ("simulate_step_us", "simulate, per step"),
        ("bdf_step_us", "BDF.step"),
        ("factor_us", "factorisation"),
        ("jacobian_us", "Jacobian, 12 JVPs"),
        ("model_jacobian_us", "Jacobian, element-wise"),
        ("solve_us", "one solve"),
        ("rhs_us", "one vector field"),
    ):
        ax.loglog(k, [r[col] for r in rows], "o-", label=lab)
    ax.set_xlabel("k (elements)")
    ax.set_ylabel("microseconds")
    ax.set_title("one BDF step and its pieces, displacement")
    ax.legend(fontsize=7)
    savefig(fig, name)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    main(p.parse_args().quick)
