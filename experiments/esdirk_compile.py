"""Compile and run time of the written-out Kvaerno (ESDIRK) against another commit's.

Question: what does a change of `jaxstring/_solvers/esdirk.py` do to the compile time
and the run time of the solves it serves? For each program -- the string pendulum
in natural (eps, t) and (eps, phi) variables, k = 40, EA = 1e6 N, alpha = 0.01, 2 s,
Kvaerno5 at rtol = atol = 1e-6, and (eps, t) with Kvaerno3 -- in a fresh process
without compilation cache: the XLA compilation of the lowered solve (tracing apart)
and the best of five runs of the compiled solve, for this working tree and for the
reference commit (`--ref`, checked out into a temporary git worktree), in interleaved
rounds (each code once per round); the table gives the medians over the rounds.

Run: ``python experiments/esdirk_compile.py --ref COMMIT [--rounds 3] [--quick]``.
Writes results/esdirk_compile.{md,csv}.
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys

import _common as common


ROOT = pathlib.Path(__file__).resolve().parents[1]

PROGRAMS = {
    "(eps, t) kvaerno5": ("natural", "kvaerno5"),
    "(eps, phi) kvaerno5": ("angle", "kvaerno5"),
    "(eps, t) kvaerno3": ("natural", "kvaerno3"),
}

_CHILD = """
import json, sys, time
import equinox as eqx
import jax
import jaxstring as js
from jaxstring import _integrate, _jit
formulation, solver, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
scene = js.string_pendulum(formulation, k=k, EA=1e6, alpha=0.01, t1=2.0)
config = js.SolveConfig(solver=solver, rtol=1e-6, atol=1e-6)
ts = config.save_times(scene.t0, scene.t1)
t0 = time.perf_counter()
lowered = _integrate.jit_solve_values.lower_cpu(scene, config, ts)
trace_s = time.perf_counter() - t0
options = getattr(_jit, "cpu_compiler_options", lambda: _jit.CPU_COMPILER_OPTIONS)()
t0 = time.perf_counter()
compiled = lowered.compile(options)
compile_s = time.perf_counter() - t0
# the compiled call's array arguments, as `cpu_jit` splits them (older code:
# `eqx.partition`)
_split = getattr(_jit, "split_arrays", None)
dynamic = (_split(((scene, config, ts), ()))[0] if _split else
           eqx.partition(((scene, config, ts), ()), eqx.is_array)[0])
runs = []
for _ in range(5):
    t0 = time.perf_counter()
    out = jax.block_until_ready(compiled(dynamic))
    runs.append(time.perf_counter() - t0)
print(json.dumps(dict(trace_s=trace_s, compile_s=compile_s, run_s=min(runs),
                      steps=int(out.stats["num_steps"]),
                      end=float(out.ys[-1, -1, 1]))))
"""


def _child(root, formulation, solver, k):
    env = dict(os.environ, PYTHONPATH=str(root), JAXSTRING_CACHE="off")
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, formulation, solver, str(k)],
        capture_output=True, text=True, check=True, env=env, cwd=root,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(ref, rounds=3, quick=False):
    common.set_quick(quick)
    k = 10 if quick else 40
    programs = list(PROGRAMS)[:1] if quick else list(PROGRAMS)
    rounds = 1 if quick else rounds
    with common.ref_worktree(ref) as refdir:
        codes = {"this tree": ROOT, f"ref {ref[:10]}": refdir}
        got = {(p, c): [] for p in programs for c in codes}
        for _ in range(rounds):
            for prog in programs:
                for code, root in codes.items():
                    r = _child(root, *PROGRAMS[prog], k)
                    print(prog, code, r, flush=True)
                    got[prog, code].append(r)
    rows = []
    for (prog, code), rs in got.items():
        med = lambda key: statistics.median(r[key] for r in rs)  # noqa: E731
        rows.append(dict(program=prog, code=code, compile_s=med("compile_s"),
                         run_s=med("run_s"), trace_s=med("trace_s"),
                         steps=rs[0]["steps"], end_y=rs[0]["end"],
                         rounds=len(rs)))  # fmt: skip
    common.write_table(
        "esdirk_compile",
        rows,
        list(rows[0]),
        f"Written-out Kvaerno: compile and run time, this tree against {ref[:10]} "
        f"(k = {k})",
        [
            "Each value the median over interleaved rounds, each a fresh process "
            "without compilation cache; compile_s: XLA's compilation of the lowered "
            "solve (tracing apart, trace_s); run_s: best of five runs of the compiled "
            "solve; steps, end_y: the run's step count and the end mass's height (m), "
            "equal when the change keeps the algorithm.",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--ref", required=True, help="the commit to compare against")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--quick", action="store_true")
    a = p.parse_args()
    main(a.ref, a.rounds, a.quick)
