"""Block Thomas against block cyclic reduction: compile time against run time.

Question: a block-tridiagonal Newton matrix can be eliminated from the first block
to the last (the block Thomas algorithm, one step in a `lax.scan`) or by block
cyclic reduction (log2 N levels, unrolled at trace time, each vectorised over its
blocks). Which compiles faster, which runs faster, for the block sizes of
jaxstring's chains (2: the reduced 2D displacement string; 3: 3D lines and
strings; 4: natural variables)? And what does the choice do to whole solves?

Kernels: a random diagonally dominant block-tridiagonal matrix, factorised and
solved 200 times in one compiled loop (per-solve time: the loop's time / 200,
best of 5), and the XLA compilation of that loop; both codes in one process.
Solves: the string pendulum (displacement variables, 2D, EA = 1e6 N, 2 s,
rtol = atol = 1e-6) with Kvaerno5 and BDF, each in a fresh process without
compilation cache, with `block_factor`'s sequential elimination for blocks of up
to 2 rows (jaxstring's default) and with cyclic reduction for every block size.

Run: ``python experiments/block_elimination.py [--quick]``. Writes
results/block_elimination.{md,csv} and results/block_elimination_solves.{md,csv}.
"""

import argparse
import json
import subprocess
import sys
import time

import _common as common


KERNELS = ((10, 2), (40, 2), (160, 2), (10, 3), (40, 3), (40, 4))
REPS = 200

_CHILD = """
import json, sys, time
import jax
import numpy as np
import jaxstring as js
from jaxstring import _integrate, _linalg
formulation, solver, k, max_block = sys.argv[1], sys.argv[2], int(sys.argv[3]), \\
    int(sys.argv[4])
_linalg.banded.SEQUENTIAL_MAX_BLOCK = max_block
scene = js.string_pendulum(formulation, k=k, EA=1e6, t1=2.0)
config = js.SolveConfig(solver=solver)
ts = config.save_times(scene.t0, scene.t1)
t0 = time.perf_counter()
lowered = _integrate.jit_solve.lower_cpu(scene, config, ts)
trace_s = time.perf_counter() - t0
t0 = time.perf_counter()
compiled = lowered.compile()
compile_s = time.perf_counter() - t0
import equinox as eqx
dynamic, static = eqx.partition(((scene, config, ts), ()), eqx.is_array)
runs = []
for _ in range(5):
    t0 = time.perf_counter()
    out = compiled(dynamic)
    jax.block_until_ready(out)
    runs.append(time.perf_counter() - t0)
end = np.asarray(out.end_mass[-1]).tolist()
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
    }[code]
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

    jitted = jax.jit(loop, compiler_options=_jit.CPU_COMPILER_OPTIONS)
    t0 = time.perf_counter()
    compiled = jitted.lower(mat, f).compile()
    compile_s = time.perf_counter() - t0
    compiled(mat, f).block_until_ready()
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        compiled(mat, f).block_until_ready()
        best = min(best, (time.perf_counter() - t0) / REPS)
    x = np.asarray(solve(jax.jit(factor)(mat), f))
    dense = np.asarray(mat.to_dense()) if hasattr(mat, "to_dense") else None
    err = (
        float(np.max(np.abs(dense @ x.reshape(-1) - np.asarray(f).reshape(-1))))
        if dense is not None
        else float("nan")
    )
    return dict(compile_s=compile_s, solve_us=best * 1e6, residual=err)


def main(quick=False):
    common.set_quick(quick)
    kernels = KERNELS[:2] if quick else KERNELS
    rows = []
    for N, B in kernels:
        pair = {}
        for code in ("cyclic reduction", "block Thomas"):
            pair[code] = _kernel(N, B, code)
            rows.append(dict(blocks=N, block_size=B, code=code, **pair[code]))
            print(rows[-1], flush=True)
        ref = pair["cyclic reduction"]
        for r in rows[-2:]:
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
            "blocks). Both codes pivot within the blocks (closed-form inverses "
            "up to 2 x 2), not across them.",
        ],
    )
    solves = []
    k = 10 if quick else 40
    programs = (
        (("displacement", "kvaerno5"),)
        if quick
        else (
            ("displacement", "kvaerno5"),
            ("displacement", "bdf"),
        )
    )
    for formulation, solver in programs:
        base = None
        for label, max_block in (("cyclic reduction", 0), ("block Thomas", 2)):
            out = subprocess.run(
                [
                    sys.executable,
                    "-c",
                    _CHILD,
                    formulation,
                    solver,
                    str(k),
                    str(max_block),
                ],  # fmt: skip
                capture_output=True,
                text=True,
                check=True,
            )
            r = json.loads(out.stdout.strip().splitlines()[-1])
            base = base or r
            gap = max(abs(a - b) for a, b in zip(r["end"], base["end"]))
            solves.append(
                dict(
                    program=f"{formulation} {solver}, k = {k}",
                    elimination=label,
                    trace_s=r["trace_s"],
                    compile_s=r["compile_s"],
                    run_s=r["run_s"],
                    steps=r["steps"],
                    end_mass_gap_m=gap,
                    compile_vs_reduction=r["compile_s"] / base["compile_s"],
                    run_vs_reduction=r["run_s"] / base["run_s"],
                )
            )
            print(solves[-1], flush=True)
    common.write_table(
        "block_elimination_solves",
        solves,
        list(solves[0]),
        "Whole solves: the reduced 2 x 2 systems eliminated by block Thomas or by "
        "cyclic reduction",
        [
            "Each row a fresh process without compilation cache; compile_s: XLA's "
            "compilation of the lowered solve (tracing apart: trace_s); run_s: best "
            "of 5 runs of the compiled solve; end_mass_gap_m: the end mass's "
            "largest coordinate difference at 2 s from the cyclic-reduction row.",
        ],
    )
    return rows, solves


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    main(quick=p.parse_args().quick)
