"""Sweeps on every core: members per second against CVODE-numba on as many processes.

Question: how does `jaxstring.sweep` scale with members and worker processes, and
how does it compare with the strongest peer run the same way -- CVODE BDF on a numba
right-hand side with the analytic band Jacobian (jaxstring/testing/peers.py), one
member after the other in each of the same number of worker processes (a
`ProcessPoolExecutor`, members split evenly)? Case: the default pendulum
(displacement variables, k = 40, EA = 1e6 N, alpha in [0.005, 0.05] s, 2 s), end
mass saved at 0.5, 1, 1.5, 2 s. jaxstring: `sweep` with its own defaults (BDF from
`SOLVE_DEFAULTS["sweep"]` where set, groups of `batch_size="auto"`) at rtol = atol
= `--tol`, `processes` 1, 2 and all cores. CVODE at rtol = atol = `--cvode-tol`.
Every member's end-mass error is checked against CVODE at 1e-10 (on every
`--check`-th member). Times: wall, first call (compile and worker start included)
and a second call (the user's next sweep), peak resident memory of the process
tree (max RSS of the parent and its children).

Run: ``python experiments/sweep_scale.py [--quick] [--members 64,256,1024]``.
Writes results/sweep_scale.{md,csv,png}.
"""

import argparse
import concurrent.futures as cf
import multiprocessing
import resource
import time

import _common as common
import numpy as np

import jaxstring as js
from jaxstring import _distribute
from jaxstring.testing import peers


K, EA, T1 = 40, 1e6, 2.0
TS = np.linspace(0.0, T1, 5)


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


def cvode_pool(alphas, tol, workers):
    """CVODE-numba over `workers` spawned processes (each warmed up first: numba's
    compilation is not timed), members split evenly."""
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(workers, mp_context=ctx) as pool:
        list(pool.map(_warm_peer, range(workers)))
        parts = np.array_split(alphas, workers)
        start = time.perf_counter()
        out = np.concatenate(list(pool.map(_cvode_chunk, parts, [tol] * workers)))
        return out, time.perf_counter() - start


def end_mass(traj, scene):
    del scene
    return traj.end_mass


def peak_rss_mb():
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return max(own, kids) / 1024


def main(quick=False, members=None, tol=1e-6, cvode_tol=1e-6, check=8):
    common.set_quick(quick)
    cores = _distribute.host_cores()
    members = members or ([32] if quick else [64, 256, 1024])
    workers = sorted({1, 2, cores}) if not quick else [1, 2]
    base = js.string_pendulum(k=K, EA=EA, t1=T1)
    rows = []
    for n in members:
        alphas = np.linspace(0.005, 0.05, n)
        ref = _cvode_chunk(alphas[::check], 1e-10)
        for w in workers:
            cv, cv_wall = cvode_pool(alphas, cvode_tol, w)
            cv_err = max(
                common.end_mass_error(a[1:], b[1:]) for a, b in zip(cv[::check], ref)
            )
            calls = []
            for _ in range(2):
                res, wall, _ = common.clock(
                    lambda: js.sweep(
                        base,
                        {"alpha": alphas},
                        end_mass,
                        ts=TS,
                        rtol=tol,
                        atol=tol,
                        processes=w,
                    )  # fmt: skip
                )
                calls.append(wall)
            out = np.asarray(res.out)
            err = max(
                common.end_mass_error(a[1:], b[1:]) for a, b in zip(out[::check], ref)
            )
            row = dict(
                members=n,
                processes=w,
                solver=js.SolveConfig.default("sweep").solver,
                first_call_s=calls[0],
                second_call_s=calls[1],
                members_per_s=n / calls[1],
                cvode_s=cv_wall,
                cvode_members_per_s=n / cv_wall,
                speedup_vs_cvode=cv_wall / calls[1],
                speedup_first_call=cv_wall / calls[0],
                error_m=err,
                cvode_error_m=cv_err,
                all_ok=bool(np.all(res.ok)),
                peak_rss_mb=peak_rss_mb(),
            )
            print(row, flush=True)
            rows.append(row)
        _distribute.shutdown_pool()
    common.write_table(
        "sweep_scale",
        rows,
        list(rows[0]),
        f"Sweeps over worker processes against CVODE-numba over as many processes "
        f"(pendulum k = {K}, EA = {EA:g} N, {T1} s; {cores} cores)",
        [
            f"jaxstring: sweep's defaults at rtol = atol = {tol:g}; CVODE-numba (BDF, "
            f"band, analytic Jacobian) at {cvode_tol:g}, members split evenly over "
            "the same number of spawned worker processes, numba compiled before "
            "timing. second_call_s: a second sweep of the same structure (the "
            "workers and compiled program kept); first_call_s: compile and worker "
            "start included.",
            f"error_m: largest end-mass distance from CVODE at 1e-10 over every "
            f"{check}-th member (cvode_error_m: CVODE's own).",
        ],
    )
    fig, axes = common.new_figure(1, 1, w=5.5, h=4.0)
    ax = axes[0, 0]
    for w in workers:
        sel = [r for r in rows if r["processes"] == w]
        ax.loglog([r["members"] for r in sel], [r["members_per_s"] for r in sel], "o-",
                  label=f"jaxstring, {w} process(es)")  # fmt: skip
        ax.loglog([r["members"] for r in sel], [r["cvode_members_per_s"] for r in sel],
                  "s--", label=f"CVODE-numba, {w} process(es)")  # fmt: skip
    ax.set_xlabel("members")
    ax.set_ylabel("members per second")
    ax.legend(fontsize=7)
    common.savefig(fig, "sweep_scale")
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--members", default=None)
    p.add_argument("--tol", type=float, default=1e-6)
    p.add_argument("--cvode-tol", dest="cvode_tol", type=float, default=1e-6)
    a = p.parse_args()
    members = [int(x) for x in a.members.split(",")] if a.members else None
    main(quick=a.quick, members=members, tol=a.tol, cvode_tol=a.cvode_tol)
