"""A sweep split over two `jax.distributed` processes against one process.

Question: on one 2-core machine, how much of a sweep's wall time do two processes of
a `jax.distributed` job (127.0.0.1, one per core; each runs its block of members
and gathers every member's result) save against one process alone? Case: the
default pendulum of `sweep_scale.py` (displacement variables, k = 40, EA = 1e6 N,
2 s, alpha in [0.005, 0.05] s, end mass at 0.5, 1, 1.5, 2 s), `--members` members,
`sweep`'s defaults (`processes=1` in each process: the job is the parallelism).
Times: the first call (compile included) and the median of three later calls of
the same sweep in each process; for the job, the slower of its two processes. The
results of the two processes are compared with one process's, member by member.

Run: ``python experiments/sweep_distributed.py [--members 64]``. Writes
results/sweep_distributed.{md,csv}.
"""

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time

import numpy as np


K, EA, T1 = 40, 1e6, 2.0
TS = np.linspace(0.0, T1, 5)


def _end_mass(traj, scene):
    # One function object for every call: a new lambda per call is a new static
    # argument, so each call would compile the sweep again.
    return traj.end_mass


def _sweep(members):
    import jaxstring as js

    times, res = [], None
    for _ in range(4):
        start, cpu = time.perf_counter(), time.process_time()
        res = js.sweep(
            js.string_pendulum(k=K, EA=EA, t1=T1),
            {"alpha": np.linspace(0.005, 0.05, members)},
            _end_mass,
            ts=TS,
            processes=1,
        )
        times.append((time.perf_counter() - start, time.process_time() - cpu))
    return res, times


def child(address, process_id, members, out):
    """One process of the job (and, with `address` "-", the lone process)."""
    if address != "-":
        import jax

        jax.distributed.initialize(
            coordinator_address=address,
            num_processes=2,
            process_id=process_id,
            initialization_timeout=120,
        )
    res, times = _sweep(members)
    np.savez(out, out=np.asarray(res.out), result=res.result)
    with open(out + ".json", "w") as f:
        json.dump(
            {
                "first_call_s": times[0][0],
                "later_call_s": float(np.median([t[0] for t in times[1:]])),
                "later_call_cpu_s": float(np.median([t[1] for t in times[1:]])),
            },
            f,
        )
    if address != "-":
        import jax

        jax.distributed.shutdown()


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _run(address, ids, members, folder):
    # No compilation cache: every process compiles its programs (JAX writes its
    # persistent cache from process 0 of a job only, so a cache would serve the
    # lone process and process 0, not process 1).
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", JAXSTRING_CACHE="off")
    procs, outs = [], []
    for i in ids:
        out = os.path.join(folder, f"p{i}_{address.replace(':', '_')}")
        cmd = [sys.executable, __file__, "--child", address, str(i), str(members), out]
        procs.append(subprocess.Popen(cmd, env=env, start_new_session=True))
        outs.append(out)
    for p in procs:
        if p.wait(timeout=1200) != 0:
            raise RuntimeError(f"process failed: {p.args}")
    return [
        (np.load(o + ".npz"), json.load(open(o + ".json", encoding="utf-8")))
        for o in outs
    ]


def main(members=64):
    import _common as common

    folder = tempfile.mkdtemp(prefix="sweep_distributed_")
    (one, t_one), = _run("-", [0], members, folder)  # fmt: skip
    job = _run(f"127.0.0.1:{_free_port()}", [0, 1], members, folder)
    diff = max(float(np.max(np.abs(r["out"] - one["out"]))) for r, _ in job)
    same_status = all(np.array_equal(r["result"], one["result"]) for r, _ in job)
    rows = [
        dict(setup="one process", members=members, **t_one),
        dict(
            setup="jax.distributed, 2 processes",
            members=members,
            first_call_s=max(t["first_call_s"] for _, t in job),
            later_call_s=max(t["later_call_s"] for _, t in job),
            later_call_cpu_s=max(t["later_call_cpu_s"] for _, t in job),
        ),
    ]
    for r in rows:
        r["vs_one_process"] = r["later_call_s"] / rows[0]["later_call_s"]
    common.write_table(
        "sweep_distributed",
        rows,
        list(rows[0]),
        f"A {members}-member sweep as two jax.distributed processes against one "
        f"process (pendulum k = {K}, EA = {EA:g} N, {T1} s)",
        [
            "Each process: sweep's defaults, processes=1; the job on 127.0.0.1, "
            "each process running its block of members and gathering every "
            "member's result. Times of the job: the slower process. "
            "later_call_s: the median of three calls after the first; "
            "vs_one_process: later_call_s over the one process's.",
            f"Results: the largest end-mass difference of either job process from "
            f"the one process {diff:.1e} m; statuses equal: {same_status}.",
        ],
    )
    return rows


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), sys.argv[5])
    else:
        p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
        p.add_argument("--members", type=int, default=64)
        main(members=p.parse_args().members)
