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

With ``--run-once``: the programs that a user typically runs once per
structure, through their public calls -- reading MoorDyn's WD0050 deck (its static
equilibrium, start geometry and rest tensions; again: `lines.equilibrium`), the
coupled stiffness of the OC3 mooring (`lines.coupled_stiffness`), the tandem's
equilibria (`tandem.find_equilibria`, compiled tiered here only) -- each in a fresh
process without compilation cache, compiled with jaxstring's options ("full") or
with `jaxstring._jit.QUICK_OPTIONS` on top ("quick", XLA's optimisation level 0);
first_call_s: the first call (trace, compile, run), run_s: the best of five calls
after it (none promoted). Which programs `cpu_jit(..., tiered=True)` compiles
quickly first follows from it. Writes results/compile_options_run_once.{md,csv}.

Run: ``python experiments/compile_options.py [--quick] [--rounds N] [--run-once]``.
Writes results/compile_options.{md,csv}.
"""

import argparse
import json

import _common as common
import numpy as np


OPTIONS = {
    "jaxstring default": {},
    "XLA's fusion emitters": {"xla_cpu_use_fusion_emitters": True},
    "backend opt level 1": {"xla_backend_optimization_level": 1},
    "backend opt level 0": {"xla_backend_optimization_level": 0},
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
# the compiled call's array arguments, as `cpu_jit` splits them (older code:
# `eqx.partition`)
_split = getattr(_jit, "split_arrays", None)
dynamic = (_split(((scene, config, ts), ()))[0] if _split else
           eqx.partition(((scene, config, ts), ()), eqx.is_array)[0])
runs = []
for _ in range(3):
    t0 = time.perf_counter()
    out = compiled(dynamic)
    jax.block_until_ready(out)
    runs.append(time.perf_counter() - t0)
print(json.dumps(dict(trace_s=trace_s, compile_s=compile_s, run_s=min(runs),
                      steps=int(out.stats["num_steps"]))))
"""


_RUN_ONCE_CHILD = """
import json, math, sys, time
import jaxstring as js
from jaxstring import _jit
program, tier = sys.argv[1], sys.argv[2]
_jit.PROMOTE_AFTER_S = math.inf  # every call in the first tier
if tier == "full":
    _jit.QUICK_OPTIONS.clear()  # the first tier compiled as the second
if program == "WD0050 read (static equilibrium)":
    deck = js.lines.case_path("WD0050_Chain.txt")
    first = lambda: js.lines.read_moordyn(deck)
    again = lambda s: js.lines.equilibrium(s.model, s.effects, s.env)[0]
elif program == "OC3 coupled stiffness":
    system = js.lines.mooring_system(js.lines.case_path("lines.txt"), g=9.81)
    first = lambda: system
    again = lambda s: js.lines.coupled_stiffness(s)[0]
elif program == "tandem equilibria":
    from jaxstring.tandem import analysis
    analysis._equilibria_one = _jit.cpu_jit(analysis._equilibria_one_body, tiered=True)
    scene = js.tandem.tandem_equilibria(V_w=15.0, Delta_w_deg=90.0)
    first = lambda: scene
    again = lambda s: js.tandem.find_equilibria(s)
t0 = time.perf_counter()
made = first()
if program != "WD0050 read (static equilibrium)":
    out = again(made)
first_s = time.perf_counter() - t0
runs = []
for _ in range(5):
    t0 = time.perf_counter()
    out = again(made)
    getattr(out, "block_until_ready", lambda: None)()
    runs.append(time.perf_counter() - t0)
print(json.dumps(dict(first_call_s=first_s, run_s=min(runs))))
"""

RUN_ONCE = (
    "WD0050 read (static equilibrium)",
    "OC3 coupled stiffness",
    "tandem equilibria",
)


def run_once(quick=False, rounds=3):
    """Quick (level 0) against full compilation of the run-once programs."""
    common.set_quick(quick)
    rounds = 1 if quick else rounds
    programs = RUN_ONCE[:1] if quick else RUN_ONCE
    runs = {}
    for _ in range(rounds):
        for prog in programs:
            for tier in ("full", "quick"):
                r = common.child_json(
                    _RUN_ONCE_CHILD, prog, tier, env={"JAXSTRING_CACHE": "off"}
                )
                print(prog, tier, r, flush=True)
                runs.setdefault((prog, tier), []).append(r)
    rows = []
    for prog in programs:
        med = {
            (tier, f): float(np.median([r[f] for r in runs[prog, tier]]))
            for tier in ("full", "quick")
            for f in ("first_call_s", "run_s")
        }
        for tier in ("full", "quick"):
            rows.append(
                dict(
                    program=prog,
                    tier=tier,
                    first_call_s=med[tier, "first_call_s"],
                    run_s=med[tier, "run_s"],
                    first_call_saved_s=med["full", "first_call_s"]
                    - med[tier, "first_call_s"],
                    run_vs_full=med[tier, "run_s"] / med["full", "run_s"],
                    rounds=len(runs[prog, tier]),
                )
            )
    common.write_table(
        "compile_options_run_once",
        rows,
        list(rows[0]),
        "Run-once programs compiled quickly (XLA's optimisation level 0) or fully",
        [
            "Each value the median over `rounds` interleaved rounds, each a fresh "
            "process without compilation cache; first_call_s: the first call, "
            "tracing and compilation included (WD0050: `read_moordyn`, which "
            "solves the static state); run_s: the best of five later calls, "
            "compiled as the first (WD0050: `lines.equilibrium`); "
            "first_call_saved_s: the full row's first call less this row's.",
        ],
    )
    return rows


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
    p.add_argument("--run-once", action="store_true")
    a = p.parse_args()
    if a.run_once:
        run_once(quick=a.quick, rounds=a.rounds)
    else:
        main(quick=a.quick, rounds=a.rounds)
