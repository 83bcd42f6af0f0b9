"""Block Thomas against block cyclic reduction: compile time against run time.

Question: a block-tridiagonal Newton matrix can be eliminated from the first block
to the last (the block Thomas algorithm, one step in a `lax.scan`) or by block
cyclic reduction (log2 N levels, unrolled at trace time, each vectorised over its
blocks). Which compiles faster, which runs faster, for the block sizes of
jaxstring's chains (2: the reduced 2D displacement string; 3: 3D strings and
mooring lines; 6: natural variables)? And what does the choice do to whole
solves? For 3 x 3 and 4 x 4 blocks, also: the reduction with the blocks inverted
by pivoted Gauss-Jordan elimination instead of in closed form.

Kernels: a random diagonally dominant block-tridiagonal matrix, factorised and
solved 200 times in one compiled loop (per-solve time: the loop's time / 200,
best of 5), and the XLA compilation of that loop; all codes in one process.
Solves: the string pendulum (EA = 1e6 N, 2 s, rtol = atol = 1e-6; displacement
variables in 2D and 3D, natural variables), MoorDyn's WD0050 chain heaved by
ZZP1_A1 (rtol = atol = 1e-4) and its BodiesAndRods deck (a body, two rods, six
lines; 1 s, rtol = atol = 1e-2), each in fresh processes without compilation cache,
with the block Thomas algorithm for every block size and with cyclic reduction
for every block size (jaxstring's default: Thomas up to 2 x 2 blocks on the CPU).

Run: ``python experiments/block_elimination.py [--quick] [--only kernels|solves]``.
Writes results/block_elimination.{md,csv} and
results/block_elimination_solves.{md,csv}.
"""

import argparse
import time

import _common as common
import numpy as np


KERNELS = ((10, 2), (40, 2), (160, 2), (10, 3), (40, 3), (160, 3), (40, 4), (40, 6))
SOLVE_REPEATS = 3
PIVOTED = "cyclic reduction, pivoted inverses"
REPS = 200

_CHILD = """
import json, sys, time
import jax
import numpy as np
import jaxstring as js
from jaxstring import _integrate, _jit, _linalg
formulation, solver, k, max_block = sys.argv[1], sys.argv[2], int(sys.argv[3]), \\
    int(sys.argv[4])
_linalg.banded.SEQUENTIAL_MAX_BLOCK = max_block
if max_block == 0:  # cyclic reduction, also where the model prefers the sequential
    _linalg.declared_sequential = lambda *args, **kwargs: False
if formulation == "WD0050":
    scene = js.lines.read_moordyn(js.lines.case_path("WD0050_Chain.txt"),
        motion=js.lines.case_path("QuasiStatic/ZZP1_A1.txt"))
    config = js.SolveConfig(solver=solver, rtol=1e-4, atol=1e-4)
elif formulation == "BodiesAndRods":
    scene = js.lines.read_moordyn(js.lines.case_path("BodiesAndRods.dat"),
        t1=1.0, static=False)
    config = js.SolveConfig(solver=solver, rtol=1e-2, atol=1e-2)
else:
    dim = 3 if formulation.endswith("3d") else 2
    scene = js.string_pendulum(formulation.removesuffix("3d"), k=k, EA=1e6,
        t1=2.0, dim=dim)
    config = js.SolveConfig(solver=solver)
ts = config.save_times(scene.t0, scene.t1)
t0 = time.perf_counter()
lowered = _integrate.jit_solve_values.lower_cpu(scene, config, ts)
trace_s = time.perf_counter() - t0
t0 = time.perf_counter()
compiled = lowered.compile()
compile_s = time.perf_counter() - t0
import equinox as eqx
# the compiled call's array arguments, as `cpu_jit` splits them (older code:
# `eqx.partition`)
_split = getattr(_jit, "split_arrays", None)
dynamic = (_split(((scene, config, ts), ()))[0] if _split else
           eqx.partition(((scene, config, ts), ()), eqx.is_array)[0])
runs = []
for _ in range(5):
    t0 = time.perf_counter()
    out = compiled(dynamic)
    jax.block_until_ready(out)
    runs.append(time.perf_counter() - t0)
end = np.asarray(out.ys[-1]).ravel().tolist()
print(json.dumps(dict(trace_s=trace_s, compile_s=compile_s, run_s=min(runs),
                      steps=int(out.stats["num_steps"]), end=end)))
"""


def _kernel(N, B, code):
    import jax
    import jax.numpy as jnp
    import numpy as np
    from jax import lax

    from jaxstring import _jit, _linalg

    factor, solve = {
        "cyclic reduction": (_linalg.bcr_factor, _linalg.bcr_solve),
        "block Thomas": (_linalg.thomas_factor, _linalg.thomas_solve),
        PIVOTED: (_linalg.bcr_factor, _linalg.bcr_solve),
    }[code]
    banded = _linalg.banded
    closed_form = banded.small_inv
    if code == PIVOTED:  # the blocks inverted by the pivoted elimination
        banded.small_inv = banded.pivoted_inverse
    rng = np.random.default_rng(N * 10 + B)
    L, D, U = (rng.standard_normal((N, B, B)) for _ in range(3))
    D += 4 * B * np.eye(B)
    mat = _linalg.BlockTridiagonal(*map(jnp.asarray, (L, D, U)), N, B, 1)
    f = jnp.asarray(rng.standard_normal((N, B)))

    def loop(m, f):
        def body(i, acc):
            # a new matrix each round, so that nothing is hoisted out of the loop
            scaled = _linalg.BlockTridiagonal(
                m.lower * (1.0 + 1e-9 * i), m.diag, m.upper, N, B, 1
            )
            return acc + solve(factor(scaled), f + 1e-12 * acc)

        return lax.fori_loop(0, REPS, body, jnp.zeros_like(f)) / REPS

    jitted = jax.jit(loop, compiler_options=_jit.cpu_compiler_options())
    try:
        t0 = time.perf_counter()
        compiled = jitted.lower(mat, f).compile()
        compile_s = time.perf_counter() - t0
        x = np.asarray(jax.jit(lambda m, f: solve(factor(m), f))(mat, f))
    finally:
        banded.small_inv = closed_form
    compiled(mat, f).block_until_ready()
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        compiled(mat, f).block_until_ready()
        best = min(best, (time.perf_counter() - t0) / REPS)
    dense = np.asarray(mat.to_dense()) if hasattr(mat, "to_dense") else None
    err = (
        float(np.max(np.abs(dense @ x.reshape(-1) - np.asarray(f).reshape(-1))))
        if dense is not None
        else float("nan")
    )
    return dict(compile_s=compile_s, solve_us=best * 1e6, residual=err)


def main(quick=False, only=None):
    common.set_quick(quick)
    rows = [] if only == "solves" else kernel_table(quick)
    solves = [] if only == "kernels" else solve_table(quick)
    return rows, solves


def kernel_table(quick):
    kernels = KERNELS[:2] if quick else KERNELS
    rows = []
    for N, B in kernels:
        pair = {}
        codes = ("cyclic reduction", "block Thomas")
        if 3 <= B <= 4:
            codes += (PIVOTED,)
        for code in codes:
            pair[code] = _kernel(N, B, code)
            rows.append(dict(blocks=N, block_size=B, code=code, **pair[code]))
            print(rows[-1], flush=True)
        ref = pair["cyclic reduction"]
        for r in rows[-len(codes) :]:
            r["compile_vs_reduction"] = r["compile_s"] / ref["compile_s"]
            r["solve_vs_reduction"] = r["solve_us"] / ref["solve_us"]
    columns = [
        "blocks",
        "block_size",
        "code",
        "compile_s",
        "solve_us",
        "compile_vs_reduction",
        "solve_vs_reduction",
        "residual",
    ]
    common.write_table(
        "block_elimination",
        rows,
        columns,
        "Block-tridiagonal elimination: block Thomas against cyclic reduction",
        [
            "compile_s: XLA's compilation of a loop of 200 factorisations and solves; "
            "solve_us: one factorisation and solve (the loop's time / 200, best of "
            "5); residual: max |A x - f| of one solve (random diagonally dominant "
            "blocks). The blocks are inverted in closed form up to 4 x 4 (pivoted "
            "Gauss-Jordan elimination above, and in the rows 'pivoted inverses'); "
            "no code pivots across blocks.",
        ],
    )
    return rows


def solve_table(quick):
    solves = []
    k = 10 if quick else 40
    programs = (
        (("displacement", "kvaerno5"),)
        if quick
        else (
            ("displacement", "kvaerno5"),
            ("displacement", "bdf"),
            ("displacement3d", "kvaerno5"),
            ("displacement3d", "bdf"),
            ("WD0050", "kvaerno5"),
            ("BodiesAndRods", "bdf"),
            ("BodiesAndRods", "kvaerno5"),
            ("natural", "kvaerno5"),
        )
    )
    modes = (("cyclic reduction", 0), ("block Thomas", 8))
    for formulation, solver in programs:
        # Fresh processes, the two eliminations alternating, REPEATS times each: the
        # median compile time and the best run (the machine is shared).
        runs = {label: [] for label, _ in modes}
        for _ in range(1 if quick else SOLVE_REPEATS):
            for label, max_block in modes:
                r = common.child_json(
                    _CHILD, formulation, solver, k, max_block,
                    env={"JAXSTRING_CACHE": "off"},
                )  # fmt: skip
                runs[label].append(r)
        base = None
        for label, _ in modes:
            rs = runs[label]
            r = dict(
                trace_s=float(np.median([x["trace_s"] for x in rs])),
                compile_s=float(np.median([x["compile_s"] for x in rs])),
                run_s=min(x["run_s"] for x in rs),
                steps=rs[0]["steps"],
                end=rs[0]["end"],
            )
            base = base or r
            scale = max(abs(b) for b in base["end"])
            gap = max(abs(a - b) for a, b in zip(r["end"], base["end"])) / scale
            program = {
                "WD0050": "WD0050 + ZZP1_A1",
                "BodiesAndRods": "BodiesAndRods, 1 s",
            }.get(formulation, f"{formulation} k = {k}")
            solves.append(
                dict(
                    program=f"{program}, {solver}",
                    elimination=label,
                    trace_s=r["trace_s"],
                    compile_s=r["compile_s"],
                    run_s=r["run_s"],
                    steps=r["steps"],
                    end_state_gap=gap,
                    compile_vs_reduction=r["compile_s"] / base["compile_s"],
                    run_vs_reduction=r["run_s"] / base["run_s"],
                )
            )
            print(solves[-1], flush=True)
    common.write_table(
        "block_elimination_solves",
        solves,
        list(solves[0]),
        "Whole solves: the Newton systems eliminated by block Thomas or by cyclic "
        "reduction",
        [
            "Each program run in 3 fresh processes per elimination (alternating), "
            "without compilation cache; compile_s: XLA's compilation of the lowered "
            "solve, the median (tracing apart: trace_s); run_s: the best of 5 runs "
            "of the compiled solve in any of them; end_state_gap: the largest "
            "difference of the final state from the cyclic-reduction row, relative "
            "to its largest entry. Block sizes: displacement 2 x 2 (reduced to the "
            "velocities), displacement3d and WD0050 3 x 3, natural 6 x 6, "
            "BodiesAndRods 42 x 42 (a node band 7 rows wide around its body; "
            "rtol = atol = 1e-2, the loosest of its equal-agreement search). Both "
            "eliminations of a model that prefers the sequential one (the lines) are "
            "forced here.",
        ],
    )
    return solves


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--only", choices=("kernels", "solves"), help="one of the tables")
    a = p.parse_args()
    main(quick=a.quick, only=a.only)
