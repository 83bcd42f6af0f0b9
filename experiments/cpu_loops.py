"""XLA:CPU's small-while-loop threshold: solve time and compile time of whole loops
compiled as one kernel.

Question: XLA:CPU runs a while loop as a sequence of kernels per iteration (its
thunk runtime), unless the loop's buffers are smaller than a threshold
(`xla_cpu_small_while_loop_byte_threshold`, 1 kB by default), in which case the
whole loop is one compiled function. An adaptive solve is a loop of small
kernels (a BDF step at k = 40 launches about 1300), so the dispatch between
kernels can cost more than the arithmetic. How much faster are jaxstring's solves
and sweeps with a larger threshold, what does it cost in compile time, and do the
results change?

The threshold can only be set process-wide (`XLA_FLAGS`, read once when the
process starts XLA; per-compilation options cannot carry it), so each row runs
in a fresh process without compilation cache. Cases: the default string
pendulum (`js.string_pendulum()`) with `simulate`'s defaults (Kvaerno5, the
solve of `jaxstring run string-pendulum`) and with BDF, the natural-variables
pendulum with
Kvaerno5 and the angle form with Rodas5P (k = 40), a sweep of 32 dampings of the
default pendulum in one vmapped group (`processes=1`), and MoorDyn's WD0050 deck
with the ZZP1_A1 motion (read before timing). Times: first call (trace and
compile included) and the best of three calls after it.

Run: ``python experiments/cpu_loops.py [--quick] [--thresholds default,1M,8M]
[--cases NAME,...]``.
Writes results/cpu_loops.{md,csv}.
"""

import json

import _common as common


FLAG = "xla_cpu_small_while_loop_byte_threshold"
COLUMNS = (
    "case threshold first_call_s run_s steps run_vs_default first_vs_default max_diff"
).split()

# case -> code run in the child: defines `build()` (untimed) and `call(x)` (timed),
# which returns the result to compare and the number of accepted steps.
PENDULUM_CASE = """
def build():
    return js.string_pendulum(formulation=%r)
def call(scene):
    tr = js.simulate(scene, **%r)
    return tr.end_mass, tr.stats["num_accepted_steps"]
"""

CASES = {
    "default pendulum (Kvaerno5)": PENDULUM_CASE % ("displacement", {}),
    "default pendulum (BDF)": PENDULUM_CASE % ("displacement", {"solver": "bdf"}),
    "natural pendulum (Kvaerno5)": PENDULUM_CASE % ("natural", {"solver": "kvaerno5"}),
    "angle pendulum (Rodas5P)": PENDULUM_CASE % ("angle", {"solver": "rodas5p"}),
    "sweep of 32 dampings (one group)": """
def build():
    return js.string_pendulum()
def call(scene):
    r = js.sweep(scene, {"alpha": np.linspace(0.005, 0.05, 32)}, processes=1)
    leaves = jax.tree_util.tree_leaves(r.out)
    return np.concatenate([np.ravel(x) for x in leaves]), r.stats["num_accepted_steps"]
""",
    "WD0050 + ZZP1_A1": """
def build():
    return js.lines.read_moordyn(
        js.lines.case_path("WD0050_Chain.txt"),
        motion=js.lines.case_path("QuasiStatic/ZZP1_A1.txt"),
    )
def call(scene):
    tr = js.simulate(scene)
    return tr.positions, tr.stats["num_accepted_steps"]
""",
}

CHILD = """
import json, sys, time
import numpy as np
import jax
import jaxstring as js
{case}
scene = build()
def timed():
    t = time.perf_counter()
    out, steps = call(scene)
    out = np.asarray(jax.block_until_ready(out))
    return time.perf_counter() - t, out, int(np.max(np.asarray(steps)))
first, out, steps = timed()
runs = [timed()[0] for _ in range(3)]
np.save(sys.argv[1], out)
print(json.dumps(dict(first_call_s=first, run_s=min(runs), steps=steps)))
"""


def _bytes(text: str) -> int:
    text = text.strip().lower()
    scale = {"k": 1024, "m": 1024**2, "g": 1024**3}.get(text[-1:], 1)
    return int(float(text.rstrip("kmg")) * scale)


def main(quick=False, thresholds=None, cases=None):
    """Each case at each threshold (default: 1 kB, 1 MB, 8 MB; quick: the default
    pendulum at 1 kB and 1 MB); return the rows."""
    import os
    import tempfile

    import numpy as np

    common.set_quick(quick)
    if quick:
        thresholds, cases = thresholds or ("default", "1M"), cases or list(CASES)[:1]
    thresholds = thresholds or ("default", "1M", "8M")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases or list(CASES):
            base = None
            for th in thresholds:
                env = {"JAXSTRING_CACHE": "off"}
                flags = os.environ.get("XLA_FLAGS", "")
                if th != "default":
                    flags += f" --xla_backend_extra_options={FLAG}={_bytes(th)}"
                env["XLA_FLAGS"] = flags.strip()
                path = os.path.join(tmp, "out.npy")
                rec = common.child_json(CHILD.format(case=CASES[case]), path, env=env)
                out = np.load(path)
                if base is None:
                    base = (rec, out)
                row = dict(
                    case=case,
                    threshold=th,
                    first_call_s=rec["first_call_s"],
                    run_s=rec["run_s"],
                    steps=rec["steps"],
                    run_vs_default=rec["run_s"] / base[0]["run_s"],
                    first_vs_default=rec["first_call_s"] / base[0]["first_call_s"],
                    max_diff=float(np.max(np.abs(out - base[1]))),
                )
                print(json.dumps(row), flush=True)
                rows.append(row)
    common.write_table(
        "cpu_loops",
        rows,
        COLUMNS,
        "XLA:CPU small-while-loop threshold: first call and solve time",
        notes=[
            f"threshold: `--xla_backend_extra_options={FLAG}=<bytes>` in XLA_FLAGS "
            "(default: XLA's own, 1 kB); each row a fresh process, no compilation "
            "cache.",
            "first_call_s: trace, compile and one solve; run_s: best of three "
            "calls after it; ratios against the default row of the same case.",
            "max_diff: largest difference of the case's result (end-mass path, "
            "or node positions) from the default row's, in m.",
        ],
    )
    return rows


if __name__ == "__main__":
    common.run_study(main, lists={"thresholds": str, "cases": str})
