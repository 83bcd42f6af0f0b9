"""Where the default test run's time goes.

Question: the README's test command (``python -m pytest -n 2``, slow tests left
out) is compile-bound; how much of its time is XLA compiling, how much tracing
and lowering, how many programs does it compile, and which files and tests cost
most? Runs the command once with a plugin (`_suite_profile_plugin.py`) that
records JAX's compile-time events per test (the process-wide
`jax.monitoring` durations of tracing, lowering to MLIR and XLA's compilation),
summed over both workers; tests that start processes of their own (the command,
the README's examples, worker pools) count those processes' time as wall time
only.

Run: ``python experiments/suite_profile.py [--quick] [-- PYTEST ARGS]``.
Writes results/suite_profile.{md,csv} (the whole run, the costliest files and
tests) and results/suite_profile_tests.csv (every test).
"""

import argparse
import collections
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

import _common as common


ROOT = pathlib.Path(__file__).resolve().parents[1]
PLUGIN = "_suite_profile_plugin"
FIELDS = ("wall_s", "compile_s", "trace_s", "lower_s", "compilations")


def main(quick=False, pytest_args=()):
    common.set_quick(quick)
    args = list(pytest_args) or (
        ["tests/pendulum/test_effects.py"] if quick else ["-n", "2"]
    )
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, SUITE_PROFILE_DIR=tmp)
        env["PYTHONPATH"] = os.pathsep.join(
            [str(ROOT / "experiments"), env.get("PYTHONPATH", "")]
        )
        start = time.perf_counter()
        command = [sys.executable, "-m", "pytest", "-q", "-p", PLUGIN, *args]
        out = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
        run_s = time.perf_counter() - start
        summary = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
        tests = {}
        for f in pathlib.Path(tmp).glob("*.json"):
            tests.update(json.loads(f.read_text()))
    total = collections.Counter()
    files = collections.defaultdict(collections.Counter)
    for test, rec in tests.items():
        total.update(rec)
        files[test.split("::")[0]].update(rec)
    rows = [dict(part="all tests", **{k: total[k] for k in FIELDS}, tests=len(tests))]
    for name, rec in sorted(files.items(), key=lambda kv: -kv[1]["wall_s"])[:25]:
        n = sum(1 for t in tests if t.startswith(name + "::"))
        rows.append(dict(part=name, **{k: rec[k] for k in FIELDS}, tests=n))
    top = sorted(tests.items(), key=lambda kv: -kv[1]["wall_s"])[:25]
    rows += [dict(part=t, **{k: r.get(k, 0) for k in FIELDS}, tests=1) for t, r in top]
    every = sorted(tests.items(), key=lambda kv: -kv[1].get("wall_s", 0))
    common.write_csv(
        "suite_profile_tests.csv",
        [dict(test=t, **{k: round(r.get(k, 0), 3) for k in FIELDS}) for t, r in every],
        ["test", *FIELDS],
        comments=[f"Every test of the default test run: {' '.join(args)}"],
    )
    share = lambda k: 100 * total[k] / max(total["wall_s"], 1e-9)  # noqa: E731
    common.write_table(
        "suite_profile",
        rows,
        ["part", *FIELDS, "tests"],
        f"The default test run: {' '.join(args)} ({run_s:.0f} s; {summary})",
        [
            f"Wall time of the command {run_s:.0f} s; the tests' wall time summed "
            f"over the workers {total['wall_s']:.0f} s, of which XLA compilation "
            f"{share('compile_s'):.0f} %, tracing {share('trace_s'):.0f} % and "
            f"lowering {share('lower_s'):.0f} % ({int(total['compilations'])} "
            "compilations).",
            "Rows: the whole run, then the 25 costliest files, then the 25 "
            "costliest tests; seconds summed over the tests of the row, each in "
            "the worker that ran it. Processes a test starts count as its wall "
            "time only.",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("pytest_args", nargs="*")
    a = p.parse_args()
    main(a.quick, a.pytest_args)
