"""XLA:CPU's compile options against compile time and run time of jaxstring's solves.

Question: which per-compilation XLA options shorten the compilation of a solve
without slowing its run? For each program -- the default scene (displacement
variables, k = 40, Kvaerno5 with a Jacobian per stage), natural variables (eps, t)
with the written-out Kvaerno5, the displacement string with BDF, (eps, phi) with
Rodas5P; 2 s, rtol = atol = 1e-6 -- and each option set, in a fresh process (no
compilation cache): the XLA compilation alone (`lower(...).compile()`, tracing
apart) and the best of three runs of the compiled solve; the median over
`--rounds` interleaved rounds (every option set once per round). Options are
passed per compilation, on top of jaxstring's own
(`jaxstring._jit.CPU_COMPILER_OPTIONS`; the row "XLA's fusion emitters" turns
XLA:CPU's MLIR fusion emitters back on, as without jaxstring's option).

Run: ``python experiments/compile_options.py [--quick] [--rounds N]``. Writes
results/compile_options.{md,csv}.
"""

import argparse
import json

import _common as common
import numpy as np


OPTIONS = {
    "jaxstring default": {},
    "XLA's fusion emitters": {"xla_cpu_use_fusion_emitters": True},
    "backend opt level 1": {"xla_backend_optimization_level": 1},
    "no expensive LLVM passes": {"xla_llvm_disable_expensive_passes": True},
}

PROGRAMS = {
    "displacement kvaerno5": ("displacement", "kvaerno5"),
    "natural kvaerno5": ("natural", "kvaerno5"),
    "displacement bdf": ("displacement", "bdf"),
    "angle rodas5p": ("angle", "rodas5p"),
}

_CHILD = """
import json, sys, time
import jax
import jaxstring as js
from jaxstring import _integrate, _jit
formulation, solver, k, options = sys.argv[1], sys.argv[2], int(sys.argv[3]), \\
    json.loads(sys.argv[4])
scene = js.string_pendulum(formulation, k=k, EA=1e6, t1=2.0)
config = js.SolveConfig(solver=solver)
ts = config.save_times(scene.t0, scene.t1)
t0 = time.perf_counter()
lowered = _integrate.jit_solve_values.lower_cpu(scene, config, ts)
trace_s = time.perf_counter() - t0
t0 = time.perf_counter()
compiled = lowered.compile(_jit.cpu_compiler_options() | options)
compile_s = time.perf_counter() - t0
import equinox as eqx
dynamic, static = eqx.partition(((scene, config, ts), ()), eqx.is_array)
runs = []
for _ in range(3):
    t0 = time.perf_counter()
    out = compiled(dynamic)
    jax.block_until_ready(out)
    runs.append(time.perf_counter() - t0)
print(json.dumps(dict(trace_s=trace_s, compile_s=compile_s, run_s=min(runs),
                      steps=int(out.stats["num_steps"]))))
"""


def main(quick=False, rounds=3):
    common.set_quick(quick)
    k = 10 if quick else 40
    rounds = 1 if quick else rounds
    programs = list(PROGRAMS)[:1] if quick else list(PROGRAMS)
    options = list(OPTIONS)[:2] if quick else list(OPTIONS)
    runs = {}
    for _ in range(rounds):
        for prog in programs:
            formulation, solver = PROGRAMS[prog]
            for name in options:
                r = common.child_json(
                    _CHILD,
                    formulation,
                    solver,
                    k,
                    json.dumps(OPTIONS[name]),
                    env={"JAXSTRING_CACHE": "off"},
                )
                print(prog, name, r, flush=True)
                runs.setdefault((prog, name), []).append(r)

    def median(prog, name, field):
        return float(np.median([r[field] for r in runs[prog, name]]))

    rows = []
    for prog in programs:
        base = {f: median(prog, options[0], f) for f in ("compile_s", "run_s")}
        for name in options:
            row = dict(
                program=prog,
                options=name,
                compile_s=median(prog, name, "compile_s"),
                run_s=median(prog, name, "run_s"),
                trace_s=median(prog, name, "trace_s"),
                steps=runs[prog, name][0]["steps"],
                rounds=len(runs[prog, name]),
            )
            row["compile_vs_default"] = row["compile_s"] / base["compile_s"]
            row["run_vs_default"] = row["run_s"] / base["run_s"]
            rows.append(row)
    common.write_table(
        "compile_options",
        rows,
        list(rows[0]),
        f"XLA:CPU compile options: compile and run time of simulate's solve (k = {k})",
        [
            "Each value the median over `rounds` interleaved rounds, each a fresh "
            "process without compilation cache; compile_s: XLA's compilation of the "
            "lowered solve (tracing apart, trace_s); run_s: best of three runs of "
            "the compiled solve; ratios against the row 'jaxstring default' of the "
            "same program.",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--rounds", type=int, default=3)
    a = p.parse_args()
    main(quick=a.quick, rounds=a.rounds)
