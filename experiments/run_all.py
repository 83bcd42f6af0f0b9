"""Regenerate every results file: run each study of studies.py, one after the other.

Run: ``python experiments/run_all.py [--only STUDY ...] [--quick] [--list]``.

Without ``--quick`` each study runs the commands that wrote its files in
experiments/results/ (several for some studies: variants, or parts merged into
one report), in order; with ``--quick`` each study's quick run, whose files go to
the git-ignored experiments/results/quick/. Runs that need a GPU are left out
unless ``--gpu`` is given (run them on a machine with one). Each command runs in
its own process and stamps its files (harness.py); a failed command stops the
rest unless ``--keep-going``. ``--list`` prints the studies, their expected run
times and commands, and runs nothing. Then ``python experiments/stale.py``
should list every result as fresh.
"""

import argparse
import shlex
import subprocess
import sys

import stamps
import studies
from harness import clock


def commands(study, quick=False, gpu=False):
    """The command lines (argument lists after ``python``) of a study's runs."""
    script = f"experiments/{study.script}"
    if quick:
        return [[script, *args, "--quick"] for args in study.quick]
    return [[script, *run.args] for run in study.runs if gpu or not run.gpu]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="+", metavar="STUDY", help="these studies only")
    p.add_argument("--quick", action="store_true", help="the quick runs")
    p.add_argument("--gpu", action="store_true", help="include the GPU runs")
    p.add_argument("--list", action="store_true", help="list, run nothing")
    p.add_argument("--keep-going", action="store_true", help="go on after a failure")
    a = p.parse_args(argv)
    unknown = set(a.only or ()) - set(studies.BY_NAME)
    if unknown:
        p.error(f"unknown studies {sorted(unknown)}; known: {sorted(studies.BY_NAME)}")
    chosen = [s for s in studies.STUDIES if not a.only or s.name in a.only]
    if a.list:
        for s in chosen:
            print(f"{s.name}  ({s.runtime}, quick / full): {s.question}")
            for cmd in commands(s, a.quick, gpu=True):
                gpu = any(r.gpu and list(r.args) == cmd[1:] for r in s.runs)
                print(f"    python {shlex.join(cmd)}" + ("  # GPU" if gpu else ""))
            if not a.quick:
                print(f"    -> {', '.join(s.outputs)}")
        return 0
    failed = []
    for s in chosen:
        for cmd in commands(s, a.quick, a.gpu):
            line = f"python {shlex.join(cmd)}"
            print(f"== {s.name} ({s.runtime}): {line}", flush=True)
            proc, wall, _ = clock(
                lambda c=cmd: subprocess.run([sys.executable, *c], cwd=stamps.ROOT)
            )
            print(f"== {s.name}: exit {proc.returncode} after {wall:.0f} s", flush=True)
            if proc.returncode:
                failed.append(line)
                if not a.keep_going:
                    break
        if failed and not a.keep_going:
            break
    for line in failed:
        print(f"failed: {line}")
    return int(bool(failed))


if __name__ == "__main__":
    sys.exit(main())
