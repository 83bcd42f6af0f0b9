"""What OpenBLAS threading costs on a small machine, and what jaxstring's guard saves.

Question: how long does a 160 x 160 LU factorisation take (scipy and JAX on CPU)
when OpenBLAS runs one thread per core, and inside jaxstring's calls, which limit
every loaded BLAS library to one thread while they run (`jaxstring._blas`,
threadpoolctl) and leave the user's own code as it is? Each configuration runs in
its own process, because OpenBLAS reads its thread count when it loads:

* ``threads=<cores>``: ``OPENBLAS_NUM_THREADS`` set to the core count (what an
  unset variable gives), numpy imported, jaxstring not imported;
* ``guard: numpy first``: variable unset, the user imports numpy, then jaxstring;
* ``guard: jaxstring first``: variable unset, jaxstring imported first;
* ``threads=1``: the variable set by hand.

In the guard rows the JAX LU is also timed inside jaxstring's guard (the block
its solves run in: ``jax_lu_guarded_ms``), with the pool size seen there; the
other columns are the user's own calls, outside it.

Run: ``python experiments/blas_threads.py [--quick]``.
"""

import argparse
import json
import os
import subprocess
import sys

from _common import new_figure, savefig, set_quick, write_table


N = 160

_CHILD = r"""
import json, os, statistics, sys, time
mode, n, reps = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
if mode == "guard_jaxstring_first":
    import jaxstring  # the guard under test, before numpy loads OpenBLAS
import numpy as np
if mode == "guard_numpy_first":
    import jaxstring  # the guard under test, after numpy loaded OpenBLAS
import scipy.linalg
import jax, jax.numpy as jnp
jax.config.update("jax_enable_x64", True)
rng = np.random.default_rng(0)
a = rng.standard_normal((n, n)) + n * np.eye(n)
def med(fn):
    fn()
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter(); fn(); ts.append(time.perf_counter() - t0)
    return statistics.median(ts)
aj = jnp.asarray(a)
lu = jax.jit(jax.scipy.linalg.lu_factor)
def live():
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return -1
    pools = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
    return max(pools, default=-1)
row = {
    "scipy_lu_ms": 1e3 * med(lambda: scipy.linalg.lu_factor(a)),
    "jax_lu_ms": 1e3 * med(lambda: jax.block_until_ready(lu(aj))),
    "blas_threads_live": live(),
    "env": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
}
if mode.startswith("guard"):
    from jaxstring._blas import one_blas_thread
    with one_blas_thread():
        row["jax_lu_guarded_ms"] = 1e3 * med(lambda: jax.block_until_ready(lu(aj)))
        row["blas_threads_in_call"] = live()
    row["blas_threads_after"] = live()
print(json.dumps(row))
"""

MODES = {
    "threads=cores": {"OPENBLAS_NUM_THREADS": str(os.cpu_count())},
    "guard: numpy first": None,
    "guard: jaxstring first": None,
    "threads=1": {"OPENBLAS_NUM_THREADS": "1"},
}
CHILD_MODE = {
    "threads=cores": "plain",
    "guard: numpy first": "guard_numpy_first",
    "guard: jaxstring first": "guard_jaxstring_first",
    "threads=1": "plain",
}


def run_mode(label, reps):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env.update(MODES[label] or {})
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, CHILD_MODE[label], str(N), str(reps)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    row = json.loads(out.stdout.strip().splitlines()[-1])
    row["config"] = label
    return row


def main(quick=False):
    set_quick(quick)
    reps = 20 if quick else 200
    rows = [run_mode(label, reps) for label in MODES]
    base = next(r for r in rows if r["config"] == "threads=1")
    for r in rows:
        r["scipy_vs_1thread"] = r["scipy_lu_ms"] / base["scipy_lu_ms"]
        r["jax_vs_1thread"] = r["jax_lu_ms"] / base["jax_lu_ms"]
        if "jax_lu_guarded_ms" in r:
            r["guarded_vs_1thread"] = r["jax_lu_guarded_ms"] / base["jax_lu_ms"]
        print(
            f"{r['config']:24s} scipy {r['scipy_lu_ms']:8.3f} ms  jax "
            f"{r['jax_lu_ms']:8.3f} ms  live BLAS threads {r['blas_threads_live']}"
        )
    tag = "_quick" if quick else ""
    write_table(
        f"blas_threads{tag}",
        rows,
        (
            "config env blas_threads_live scipy_lu_ms jax_lu_ms scipy_vs_1thread "
            "jax_vs_1thread blas_threads_in_call jax_lu_guarded_ms guarded_vs_1thread "
            "blas_threads_after"
        ).split(),
        f"{N} x {N} LU factorisation vs OpenBLAS threads (median of {reps})",
        notes=[
            "Each row is its own process (OpenBLAS reads its thread count on load).",
            "blas_threads_live: OpenBLAS pool size seen by threadpoolctl "
            "(-1: not installed).",
            "x_vs_1thread: time / the threads=1 row's JAX (or scipy) LU, same run.",
            "guard rows: blas_threads_in_call and jax_lu_guarded_ms inside "
            "jaxstring's guard (`jaxstring._blas.one_blas_thread`, the block its "
            "solves run in); blas_threads_after: the pool once the block is left; "
            "the other columns are the user's own calls outside it.",
        ],
    )
    fig, axes = new_figure(1, 1)
    ax = axes[0, 0]
    x = range(len(rows))
    ax.bar([i - 0.2 for i in x], [r["scipy_lu_ms"] for r in rows], 0.4, label="scipy")
    ax.bar([i + 0.2 for i in x], [r["jax_lu_ms"] for r in rows], 0.4, label="JAX")
    ax.set_xticks(list(x), [r["config"] for r in rows], rotation=15, fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel(f"{N} x {N} LU, ms (median)")
    ax.legend()
    savefig(fig, f"blas_threads{tag}")
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    main(**vars(p.parse_args()))
