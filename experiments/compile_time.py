"""Compile time of a pendulum simulate (target: below 10 s; no recompilation
when only parameter values change).

For each solver, in a fresh process with jaxstring's compilation cache off
(``JAXSTRING_CACHE=off``, so that nothing is read from an earlier process or from
another solver's compilation; JAX's start-up is paid by a tiny warm-up solve first):
the first
`simulate` call (trace, lower, XLA compile, run), the same call again (run only),
and a call with other parameter values (EA x 2, alpha x 2: must not recompile, so
it costs a run). Compile time = first call - second call. Two modes: the band of
the Newton matrix declared by the string model (`SolverStructure.bandwidth`,
the default) and detected by probing (`jaxstring._linalg.banded.detect_width`, which
compiles a probe at trace time).

String pendulum, displacement variables, k = 40, EA = 1e6 N, alpha = 0.01 s, 2 s,
rtol = atol = 1e-6. Writes experiments/results/compile_time.{csv,md}.
Run: ``python experiments/compile_time.py [--quick]`` (quick: k = 10, two solvers).
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import subprocess
import sys


SOLVERS = ("rodas5p", "kvaerno5", "kvaerno3", "bdf")


def child(solver, mode, k):
    import jax
    from harness import clock

    import jaxstring as js
    from jaxstring import _linalg

    if mode == "detected":
        _linalg.declared_width = lambda *a, **kw: None
    mk = lambda EA, alpha, kk=k: js.string_pendulum(
        "displacement", k=kk, EA=EA, alpha=alpha, t1=2.0
    )
    warm = js.simulate(mk(1e4, 0.01, 3), "tsit5", n_save=3)  # JAX start-up
    jax.block_until_ready(warm.ys)

    def call(scene):
        tr, wall, cpu = clock(
            lambda: jax.block_until_ready(
                js.simulate(scene, solver, rtol=1e-6, atol=1e-6)
            )
        )
        return wall, cpu, tr

    first, first_cpu, tr = call(mk(1e6, 0.01))
    run, _, _ = call(mk(1e6, 0.01))
    other, _, tr2 = call(mk(2e6, 0.02))
    return dict(
        solver=solver,
        band=mode,
        first_call_s=first,
        first_call_cpu_s=first_cpu,
        run_s=run,
        compile_s=first - run,
        other_values_s=other,
        recompiled=bool(other > 0.5 * first and other > run + 2.0),
        ok=bool(tr.ok and tr2.ok),
        steps=int(tr.stats["num_steps"]),
    )


def main(quick=False):
    from _common import set_quick

    set_quick(quick)
    from _common import write_table

    k = 10 if quick else 40
    solvers = SOLVERS[:2] if quick else SOLVERS
    rows = []
    for solver in solvers:
        for mode in ("declared", "detected"):
            out = subprocess.run(
                [sys.executable, __file__, "--child", solver, mode, str(k)],
                env=dict(os.environ, JAXSTRING_CACHE="off"),
                capture_output=True,
                text=True,
                check=True,
            )
            row = json.loads(out.stdout.strip().splitlines()[-1])
            print(row, flush=True)
            rows.append(row)
    write_table(
        "compile_time" + ("_quick" if quick else ""),
        rows,
        (
            "solver band compile_s first_call_s first_call_cpu_s run_s "
            "other_values_s recompiled ok steps"
        ).split(),
        f"Compile time of simulate: string pendulum, displacement, k = {k}, "
        "EA = 1e6 N, 2 s, rtol = atol = 1e-6",
        [
            "compile_s = first call - second call (same scene); each solver and mode "
            "in a fresh process after a tiny warm-up solve (JAX start-up).",
            "other_values_s: a third call with EA and alpha doubled; recompiled: "
            "whether it cost about a compilation (it must not).",
            "band declared: the string model's declared band (default); detected: "
            "the trace-time probe (one extra XLA compilation per new relation).",
        ],
    )


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], sys.argv[3], int(sys.argv[4]))))
        sys.exit(0)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    a = p.parse_args()
    main(quick=a.quick or bool(os.environ.get("SMOKE_TEST")))
