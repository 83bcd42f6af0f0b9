"""Sweeps on every core and GPU: members per second against CVODE-numba on every core.

Question: how does `jaxstring.sweep` scale with members, worker processes and a
GPU, and how does it compare with the strongest peer run the same way -- CVODE BDF
on a numba right-hand side with the analytic band Jacobian
(jaxstring/testing/peers.py), one member after the other in each of the same
number of worker processes (a `ProcessPoolExecutor`, members split evenly; against
a GPU, every core of the host)? Case: the default pendulum (displacement
variables, k = 40, EA = 1e6 N, alpha in [0.005, 0.05] s, 2 s), end mass saved at
0.5, 1, 1.5, 2 s. jaxstring: `sweep` with its own defaults (the solver of
`SolveConfig.default("sweep")`, `batch_size="auto"`) at rtol = atol = `--tol`, on
`processes` 1, 2 and all cores of a CPU host, or on the GPU of a GPU host
(`processes="auto"` there: this process, its GPU). `--sorted-groups G` adds, for
sweeps of more than G members, a row with groups of G members sorted by alpha.
CVODE at rtol = atol = `--cvode-tol`; with `--peer-members M` it runs M members
spread evenly over the range and its time is scaled to all members. Errors: the
end-mass distance from CVODE at 1e-10 on `--check` members spread over the range
(the same members for both). Times: wall, first call (compile and worker start
included) and a second call (the user's next sweep; sweeps of `--one-call-from`
members or more are called once), peak resident memory of the process tree, and
on a GPU its peak memory. steps_mean / steps_max: accepted steps per member (a
vmapped group runs until its slowest member is done).

Worker processes, jaxstring's and CVODE's alike, are bound one per core where a
pool has one per core (`jaxstring._distribute.pinned_cores`); `--no-pin` leaves
both to the system.

Run: ``python experiments/sweep_scale.py [--quick] [--members 64,256,1024]
[--workers 1,2,16] [--name sweep_scale_gpu] [--cpu] [--no-pin]``. Writes
results/<name>.{md,csv,png}. On a GPU machine the study runs it twice: on the GPU,
and with ``--cpu`` (JAX_PLATFORMS=cpu) on the host's cores alone.
"""

import argparse
import concurrent.futures as cf
import multiprocessing
import os
import resource
import time

import _common as common
import jax
import numpy as np

import jaxstring as js
from jaxstring import _distribute
from jaxstring.testing import peers


K, EA, T1 = 40, 1e6, 2.0
TS = np.linspace(0.0, T1, 5)
RANGE = (0.005, 0.05)


def _cvode_chunk(alphas, tol):
    out = []
    for a in alphas:
        peer = peers.make_rhs("displacement", K, EA, alpha=float(a))
        res = peers.cvode_solve(peer, TS, peer.initial_state(), tol, tol)
        out.append(
            peer.end_mass(res["ys"]) if res["ok"] else np.full((len(TS), 2), np.nan)
        )
    return np.stack(out)


def _warm_peer(_):
    return peers.make_rhs("displacement", K, EA).warmup()


_POOLS = {}


def _pin(cores, started):
    """Bind the n-th worker started to core n, as jaxstring binds its own
    (`_distribute.pinned_cores`): the peer's pool is set up the same way."""
    if cores:
        with started.get_lock():
            n = started.value
            started.value += 1
        os.sched_setaffinity(0, {cores[n % len(cores)]})


def cvode_pool(alphas, tol, workers):
    """CVODE-numba over `workers` spawned processes (each warmed up first: numba's
    compilation is not timed; the pool is kept for the script's later calls),
    members split evenly; bound one per core wherever jaxstring's workers are."""
    if workers not in _POOLS:
        ctx = multiprocessing.get_context("spawn")
        cores = _distribute.pinned_cores(workers)
        _POOLS[workers] = cf.ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=_pin,
            initargs=(cores, ctx.Value("i", 0)),
        )  # fmt: skip
        list(_POOLS[workers].map(_warm_peer, range(workers)))
    parts = np.array_split(alphas, workers)
    start = time.perf_counter()
    out = list(_POOLS[workers].map(_cvode_chunk, parts, [tol] * workers))
    return np.concatenate(out), time.perf_counter() - start


def end_mass(traj, scene):
    del scene
    return traj.end_mass


def peak_rss_mb():
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, kids) / 1024


def gpu_peak_mb():
    stats = jax.devices()[0].memory_stats() or {}
    peak = stats.get("peak_bytes_in_use")
    return None if peak is None else peak / 2**20


def spread(n, m):
    """Indices of min(n, m) members spread evenly over `n`."""
    return np.unique(np.linspace(0, n - 1, min(n, m)).round().astype(int))


def _errors(out, idx, ref):
    """Largest end-mass error of members `idx` of `out` against `ref` (in order)."""
    return max(common.end_mass_error(out[i][1:], r[1:]) for i, r in zip(idx, ref))


def main(quick=False, members=None, workers=None, tol=1e-6, cvode_tol=1e-6,
         check=64, peer_members=None, one_call_from=None, sorted_groups=None,
         name="sweep_scale"):  # fmt: skip
    common.set_quick(quick)
    cores = _distribute.host_cores()
    backend = jax.default_backend()
    members = members or ([32] if quick else [64, 256, 1024])
    if workers is None:
        workers = ["gpu"] if backend != "cpu" else sorted({1, 2, cores})
        workers = [1, 2] if quick else workers
    base = js.string_pendulum(k=K, EA=EA, t1=T1)
    rows, cvode = [], {}
    for n in members:
        alphas = np.linspace(*RANGE, n)
        idx = spread(n, check)
        ref = cvode_pool(alphas[idx], 1e-10, cores)[0]
        cv_check = cvode_pool(alphas[idx], cvode_tol, cores)[0]
        cv_err = _errors(cv_check, range(len(idx)), ref)
        ref = dict(zip(idx, ref))
        for w in workers:
            peer_w = cores if w == "gpu" else w
            pidx = spread(n, peer_members or n)
            key = (len(pidx), peer_w)
            if key not in cvode:
                cvode[key] = cvode_pool(alphas[pidx], cvode_tol, peer_w)[1] / len(pidx)
            cv_per_member = cvode[key]
            cv_wall = cv_per_member * n
            variants = [("auto", "given")]
            if sorted_groups and n > sorted_groups:
                variants.append((sorted_groups, "sort"))
            for batch_size, order in variants:
                calls = []
                for _ in range(1 if one_call_from and n >= one_call_from else 2):
                    res, wall, _ = common.clock(
                        lambda: js.sweep(
                            base,
                            {"alpha": alphas},
                            end_mass,
                            ts=TS,
                            rtol=tol,
                            atol=tol,
                            processes="auto" if w == "gpu" else w,
                            batch_size=batch_size,
                            order=order,
                        )  # fmt: skip
                    )
                    calls.append(wall)
                out = np.asarray(res.out)
                steps = np.asarray(res.stats["num_steps"])
                best = calls[-1]
                row = dict(
                    members=n,
                    processes="1 + GPU" if w == "gpu" else w,
                    pinned=w != "gpu" and _distribute.pinned_cores(w) is not None,
                    groups="auto" if batch_size == "auto" else f"{batch_size}, sorted",
                    solver=js.SolveConfig.default("sweep").solver,
                    first_call_s=calls[0],
                    second_call_s=calls[1] if len(calls) > 1 else None,
                    members_per_s=n / best,
                    cvode_processes=peer_w,
                    cvode_members=len(pidx),
                    cvode_s=cv_wall,
                    cvode_members_per_s=1.0 / cv_per_member,
                    speedup_vs_cvode=cv_wall / best,
                    speedup_first_call=cv_wall / calls[0],
                    error_m=_errors(out, idx, ref.values()),
                    cvode_error_m=cv_err,
                    all_ok=bool(np.all(res.ok)),
                    steps_mean=float(steps.mean()),
                    steps_max=int(steps.max()),
                    peak_rss_mb=peak_rss_mb(),
                    gpu_peak_mb=gpu_peak_mb() if w == "gpu" else None,
                )
                print(row, flush=True)
                rows.append(row)
            _distribute.shutdown_pool()
        _write(rows, name, workers, cores, backend, tol, cvode_tol, check)
    for pool in _POOLS.values():
        pool.shutdown()
    return rows


def _write(rows, name, workers, cores, backend, tol, cvode_tol, check):
    """Write the table and figure of the rows so far."""
    dev = jax.devices()[0]
    where = f"{cores} cores" + (
        f", {dev.platform} ({dev.device_kind})" if backend != "cpu" else ""
    )
    common.write_table(
        name,
        rows,
        list(rows[0]),
        f"Sweeps over worker processes and GPUs against CVODE-numba over as many "
        f"processes (pendulum k = {K}, EA = {EA:g} N, {T1} s; {where})",
        [
            f"jaxstring: sweep's defaults at rtol = atol = {tol:g}; CVODE-numba (BDF, "
            f"band, analytic Jacobian) at {cvode_tol:g}, members split evenly over "
            "cvode_processes spawned worker processes, numba compiled before "
            "timing; where cvode_members < members, CVODE ran that many members "
            "spread over the range and cvode_s is its time scaled to all members. "
            "second_call_s: a second sweep of the same structure (the workers and "
            "compiled program kept); first_call_s: compile and worker start "
            "included; speedup_vs_cvode and members_per_s use the last call.",
            f"error_m: largest end-mass distance from CVODE at 1e-10 over {check} "
            "members spread over the range (cvode_error_m: CVODE's own).",
            "steps_mean, steps_max: accepted steps per member; a vmapped group "
            "runs until its slowest member is done.",
            "pinned: the workers of both pools bound one per core (a pool with as "
            "many workers as cores; `--no-pin` leaves them to the system).",
        ],
    )
    fig, axes = common.new_figure(1, 1, w=5.5, h=4.0)
    ax = axes[0, 0]
    for w in workers:
        label = "1 + GPU" if w == "gpu" else w
        sel = [r for r in rows if r["processes"] == label and r["groups"] == "auto"]
        ax.loglog([r["members"] for r in sel], [r["members_per_s"] for r in sel], "o-",
                  label=f"jaxstring, {label} process(es)")  # fmt: skip
        peer = f"CVODE-numba, {sel[0]['cvode_processes']} process(es)"
        ax.loglog([r["members"] for r in sel], [r["cvode_members_per_s"] for r in sel],
                  "s--", label=peer)  # fmt: skip
    ax.set_xlabel("members")
    ax.set_ylabel("members per second")
    ax.legend(fontsize=7)
    common.savefig(fig, name)


def _ints(text):
    return [int(x) for x in text.split(",")] if text else None


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--members", default=None)
    p.add_argument("--workers", default=None, help="e.g. 1,2,16 (CPU host)")
    p.add_argument("--tol", type=float, default=1e-6)
    p.add_argument("--cvode-tol", dest="cvode_tol", type=float, default=1e-6)
    p.add_argument("--check", type=int, default=64)
    p.add_argument("--peer-members", dest="peer_members", type=int, default=None)
    p.add_argument("--one-call-from", dest="one_call_from", type=int, default=None)
    p.add_argument("--sorted-groups", dest="sorted_groups", type=int, default=None)
    p.add_argument("--name", default="sweep_scale")
    p.add_argument("--cpu", action="store_true", help="the CPU alone, beside a GPU")
    p.add_argument(
        "--no-pin",
        dest="no_pin",
        action="store_true",
        help="leave the workers of both pools to the system's placement",
    )
    a = p.parse_args()
    if a.no_pin:
        _distribute.PIN_WORKERS = False
    if a.cpu:
        jax.config.update("jax_platforms", "cpu")
    main(quick=a.quick, members=_ints(a.members), workers=_ints(a.workers),
         tol=a.tol, cvode_tol=a.cvode_tol, check=a.check, peer_members=a.peer_members,
         one_call_from=a.one_call_from, sorted_groups=a.sorted_groups,
         name=a.name)  # fmt: skip
