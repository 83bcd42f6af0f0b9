"""Time to the first result: what a new user waits for, compile included.

Question: how long does each README example, each accuracy preset and the
`jaxstring` command take from a fresh process to its first result, with an empty
compilation cache and with a warm one, and how long does `import jaxstring` add to
`import jax`? Every case runs in its own fresh process (`python -c`), the cache in
a temporary folder (`JAXSTRING_CACHE_DIR`): first with the folder empty ("cold"),
then again ("warm": the compiled and traced solves saved by the first run). Reported
per case: the import, the first call (trace, compile, run), a second call in the
same process (the run alone) and the whole process's wall time. The package is
byte-compiled first (`compileall`), as `pip install` does: an interpreter run
with PYTHONDONTWRITEBYTECODE would otherwise compile jaxstring's source in every
process.

Run: ``python experiments/first_result.py [--quick] [--only NAME ...]``. Writes
results/first_result.{md,csv}.

With ``--ref COMMIT [--rounds N]`` the cases (default: the README's) run for this
tree and for the commit (checked out into a temporary git worktree) in interleaved
rounds, cold then warm for each, and results/first_result_ref.{md,csv} give the
medians over the rounds side by side: what a change did to the first result, on
one machine at one time (``--name`` another results name for the table).
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import sys
import tempfile
import time

import _common as common


HERE = os.path.dirname(os.path.abspath(__file__))

# name -> (code run once for its first result, repeated for the second call)
_PENDULUM = "js.pendulum.string_pendulum(formulation={f!r}, k=40, EA={EA}, t1=2.0)"
CASES = {
    "readme_pendulum_natural": (
        "scene = js.pendulum.string_pendulum(formulation='natural', k=40, EA=1e6, "
        "alpha=0.01, t1=2.0)",
        "traj = js.simulate(scene, solver='kvaerno5', rtol=1e-6, atol=1e-6); "
        "traj.ys.block_until_ready()",
    ),
    "readme_default_scene": (
        "scene = js.pendulum.string_pendulum()",
        "traj = js.simulate(scene); traj.ys.block_until_ready()",
    ),
    "readme_tether": (
        "scene = js.tether.tether_fixed(method='exact', N=101, t1=70.0)",
        "traj = js.simulate(scene, solver='dopri5'); traj.ys.block_until_ready()",
    ),
    "readme_tandem": (
        "scene = js.tandem.tandem_equilibria(V_w=15.0, Delta_w_deg=90.0)",
        "eqs = js.tandem.find_equilibria(scene); "
        "traj = js.simulate(js.tandem.tandem_fishtail(t1=20000.0)); "
        "traj.ys.block_until_ready()",
    ),
    "readme_moordyn_wd0050": (
        "deck = js.lines.case_path('WD0050_Chain.txt')",
        "scene = js.lines.read_moordyn(deck, motion=js.lines.case_path("
        "'QuasiStatic/ZZP1_A1.txt')); js.lines.static_tensions(scene); "
        "traj = js.simulate(scene, 'kvaerno5', rtol=1e-4, atol=1e-4); "
        "traj.ys.block_until_ready()",
    ),
    "readme_sweep": (
        "import numpy as np; pendulum = js.pendulum.string_pendulum(k=20, t1=1.0)",
        "res = js.sweep(pendulum, {'alpha': np.linspace(0.005, 0.05, 64)}, "
        "solver='implicit_euler_fixed', dt0=0.005, batch_size=16)",
    ),
}
# Not a README example: a sweep whose chunks run long enough in the workers to pay
# for starting them (the default scene, 64 members, the sweep's defaults).
CASES["sweep_default_pendulum"] = (
    "import numpy as np; scene = js.pendulum.string_pendulum()",
    "res = js.sweep(scene, {'alpha': np.linspace(0.005, 0.05, 64)})",
)
# The MoorDyn deck again, read and solved for its static state in the setup, so
# that the first call is the simulate alone, with each solver choice.
_WD0050 = (
    "deck = js.lines.case_path('WD0050_Chain.txt'); "
    "scene = js.lines.read_moordyn(deck, motion=js.lines.case_path("
    "'QuasiStatic/ZZP1_A1.txt')); js.lines.static_tensions(scene)"
)
for _name, _kw in (
    ("kvaerno5", "'kvaerno5', rtol=1e-4, atol=1e-4"),
    ("bdf", "'bdf', rtol=1e-4, atol=1e-4"),
    ("rodas5p", "'rodas5p', rtol=1e-4, atol=1e-4"),
    ("balanced", "accuracy='balanced'"),
):
    CASES[f"moordyn_wd0050_simulate_{_name}"] = (
        _WD0050,
        f"traj = js.simulate(scene, {_kw}); traj.ys.block_until_ready()",
    )
for _preset in ("draft", "balanced", "precise"):
    for _f in ("displacement", "natural", "angle"):
        CASES[f"preset_{_preset}_{_f}"] = (
            "scene = " + _PENDULUM.format(f=_f, EA=1e6),
            f"traj = js.simulate(scene, accuracy={_preset!r}); "
            "traj.ys.block_until_ready()",
        )
    CASES[f"preset_{_preset}_tether"] = (
        "scene = js.tether.tether_fixed(method='aceam', N=21, t1=20.0)",
        f"traj = js.simulate(scene, accuracy={_preset!r}); traj.ys.block_until_ready()",
    )

_CHILD = """
import time
t0 = time.perf_counter()
import jaxstring as js
t_import = time.perf_counter() - t0
{setup}
t1 = time.perf_counter()
{call}
t_first = time.perf_counter() - t1
t2 = time.perf_counter()
{call}
t_second = time.perf_counter() - t2
import json
print(json.dumps(dict(import_s=t_import, first_call_s=t_first, second_call_s=t_second,
                      first_result_s=time.perf_counter() - t0 - t_second)))
"""


def byte_compile(tree):
    """Byte-compile the jaxstring package under `tree`, as `pip install` does."""
    subprocess.run(
        [
            sys.executable,
            "-m",
            "compileall",
            "-q",
            str(pathlib.Path(tree) / "jaxstring"),
        ],
        check=True,
    )


def run_case(name, cache, env):
    setup, call = CASES[name]
    code = _CHILD.format(setup=setup, call=call)
    start = time.perf_counter()
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=dict(env, JAXSTRING_CACHE_DIR=cache),
        capture_output=True,
        text=True,
        cwd=tempfile.gettempdir(),
    )
    wall = time.perf_counter() - start
    if out.returncode != 0:
        raise RuntimeError(f"{name}: {out.stderr[-2000:]}")
    row = json.loads(out.stdout.strip().splitlines()[-1])
    return row | {"process_s": wall}


def imports(env, repeats):
    """Wall time of `import jax` and of `import jaxstring`, fresh processes."""
    out = {}
    for what in ("jax", "jaxstring"):
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            subprocess.run(
                [sys.executable, "-c", f"import {what}"], env=env, check=True
            )
            times.append(time.perf_counter() - start)
        out[what] = min(times)
    return out


def command(env, cache):
    """`jaxstring run string-pendulum`, cold and warm."""
    exe = os.path.join(os.path.dirname(sys.executable), "jaxstring")
    rows = []
    for state in ("cold", "warm"):
        with tempfile.TemporaryDirectory() as out:
            start = time.perf_counter()
            subprocess.run(
                [exe, "run", "string-pendulum", "--out", out],
                env=dict(env, JAXSTRING_CACHE_DIR=cache),
                check=True,
                capture_output=True,
            )
            rows.append({"case": "command_string_pendulum", "cache": state,
                         "process_s": time.perf_counter() - start})  # fmt: skip
    return rows


README_CASES = [name for name in CASES if name.startswith("readme_")]


def compare(ref, rounds=3, only=None, table="first_result_ref"):
    """This tree against `ref`: each case cold then warm, per code per round."""
    names = only or README_CASES
    root = pathlib.Path(HERE).parent
    base = {k: v for k, v in os.environ.items() if k != "JAXSTRING_CACHE"}
    got = {}
    with common.ref_worktree(ref) as refdir:
        codes = {"this tree": root, f"ref {ref[:10]}": refdir}
        for tree in codes.values():
            byte_compile(tree)
        for _ in range(rounds):
            for name in names:
                for code, tree in codes.items():
                    env = dict(base, PYTHONPATH=str(tree))
                    with tempfile.TemporaryDirectory() as cache:
                        for state in ("cold", "warm"):
                            r = run_case(name, cache, env)
                            print(name, code, state, r, flush=True)
                            got.setdefault((name, state, code), []).append(r)
    keys = ("first_call_s", "first_result_s", "second_call_s")
    rows = [
        {"case": name, "cache": state, "code": code}
        | {k: statistics.median(r[k] for r in rs) for k in keys}
        | {"rounds": len(rs)}
        for (name, state, code), rs in got.items()
    ]
    common.write_table(
        table,
        rows,
        ["case", "cache", "code", *keys, "rounds"],
        f"Time to the first result: this tree against {ref[:10]}",
        [
            "Each value the median over interleaved rounds; each run a fresh "
            "process, cold: an empty compilation cache, warm: the same folder "
            "after the cold run. Columns as in first_result.md.",
        ],
    )
    return rows


def main(quick=False, only=None):
    common.set_quick(quick)
    env = {k: v for k, v in os.environ.items() if k != "JAXSTRING_CACHE"}
    env["PYTHONPATH"] = os.pathsep.join(
        [os.path.dirname(HERE), env.get("PYTHONPATH", "")]
    )
    names = only or (list(CASES)[:2] if quick else list(CASES))
    byte_compile(os.path.dirname(HERE))
    rows = []
    for name in names:
        with tempfile.TemporaryDirectory() as cache:
            for state in ("cold", "warm"):
                row = {"case": name, "cache": state} | run_case(name, cache, env)
                print(row, flush=True)
                rows.append(row)
    if not only:
        with tempfile.TemporaryDirectory() as cache:
            rows += command(env, cache)
        imp = imports(env, 1 if quick else 3)
        rows.append({"case": "import jax", "cache": "", "import_s": imp["jax"]})
        rows.append(
            {"case": "import jaxstring", "cache": "", "import_s": imp["jaxstring"]}
        )
    columns = [
        "case", "cache", "import_s", "first_call_s", "first_result_s",
        "second_call_s", "process_s",
    ]  # fmt: skip
    common.write_table(
        "first_result",
        rows,
        columns,
        "Time to the first result: README examples, presets, the command",
        [
            "Each row is a fresh process; cold: an empty compilation cache "
            "(JAXSTRING_CACHE_DIR in a new temporary folder); warm: the same folder "
            "after the cold run (compiled and traced solves saved).",
            "first_call_s: the example's solve calls, compilation included; "
            "first_result_s: from the start of `import jaxstring` to the end of "
            "the first call; second_call_s: the same calls again in the process "
            "(the run alone); process_s: the whole process, Python's start-up "
            "included.",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--only", nargs="*", default=None)
    p.add_argument("--ref", default=None, help="a commit to compare against")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument(
        "--name", default="first_result_ref", help="the --ref table's results name"
    )
    a = p.parse_args()
    if a.ref:
        compare(a.ref, a.rounds, a.only, a.name)
    else:
        main(quick=a.quick, only=a.only)
