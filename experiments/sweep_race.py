"""A 64-member parameter sweep against 64 CVODE-numba runs in the same process.

Question: is one compiled jaxstring sweep faster than the strongest peer run member
by member? Case: the pendulum in displacement variables (EA = 1e6 N, 2 s, k = 20
and 40), 64 Kelvin-Voigt constants alpha in [0.005, 0.05] s. The peer: CVODE BDF,
numba right-hand side, analytic banded Jacobian, band linear solver
(jaxstring/testing/peers.py) at rtol = atol = `--cvode-tol`, one member after the other.
jaxstring: `sweep` (`--mode` vmap or lockstep, groups of `--group` sorted by alpha,
on every device of JAX's default backend: the script sets
`--xla_force_host_platform_device_count=2`, whose two CPU devices run their shards
one after the other; a GPU runs the whole sweep) with
`--solver` (BDF, vmap mode only; Kvaerno5 also lockstep) at the loosest of `--tols`
at which every member is as accurate as CVODE's least accurate member.
Error: the largest end-mass distance at 0.5, 1, 1.5, 2 s from CVODE-numba at
rtol = atol = 1e-10, member by member. Times: wall and process CPU, minimum over
`--repeats` interleaved rounds, compile apart (the sweep's first call minus its
fastest, numba's compile or cache load).

Run: ``python experiments/sweep_race.py [--quick]``.
"""

import os


# Imported first: it gives JAX two host CPU devices (the machine's two cores) and
# one BLAS thread before JAX is imported, as for sweep_speed's own runs.
from sweep_speed import end_mass  # isort: skip

import _common as common
import numpy as np

import jaxstring as js
from jaxstring._sweep import sweep
from jaxstring.testing import peers


def _cvode_loop(k, alphas, ts, tol):
    out = []
    for a in alphas:
        peer = peers.make_rhs("displacement", k, 1e6, alpha=float(a))
        res = peers.cvode_solve(peer, ts, peer.initial_state(), tol, tol)
        out.append(
            peer.end_mass(res["ys"]) if res["ok"] else np.full((len(ts), 2), np.nan)
        )
    return np.stack(out)


def _errors(ends, refs):
    return np.array([common.end_mass_error(e[1:], r[1:]) for e, r in zip(ends, refs)])


def _device_label():
    import jax

    devs = jax.devices()
    return f"{len(devs)} {devs[0].platform} ({devs[0].device_kind})"


def race_k(k, members, solver, tols, cvode_tol, repeats, group, mode, peer_members):
    alphas = np.linspace(0.005, 0.05, members)
    # The peer runs every `stride`-th member (all of them by default); its time is
    # scaled by `stride` to the whole sweep, and the sweep's accuracy is checked on
    # those members.
    stride = members // peer_members
    picked = alphas[::stride]
    ts = np.linspace(0.0, 2.0, 5)
    numba_s = peers.make_rhs("displacement", k, 1e6).warmup()
    refs, wall, _ = common.clock(lambda: _cvode_loop(k, picked, ts, 1e-10))
    print(f"k={k}: references in {wall:.1f} s", flush=True)
    base = js.string_pendulum(k=k, EA=1e6, t1=2.0)

    def run_sweep(tol):
        res = sweep(base, {"alpha": alphas}, end_mass, solver=solver, rtol=tol,
                    atol=tol, ts=ts, mode=mode, batch_size=group, order="sort",
                    devices="auto", max_steps=common.MAX_STEPS)  # fmt: skip
        return np.asarray(res.out), bool(np.all(res.ok))

    cv_end, cv_wall, cv_cpu = common.clock(
        lambda: _cvode_loop(k, picked, ts, cvode_tol)
    )
    cv_err = _errors(cv_end, refs)
    first = None
    chosen = None
    for tol in tols:  # loose to tight: the first at which every member is as good
        (end, ok), wall, _ = common.clock(lambda: run_sweep(tol))
        first = wall if first is None else first
        err = _errors(end[::stride], refs)
        print(f"k={k} sweep {solver} tol={tol:g}: ok={ok} max err "
              f"{np.max(err):.2e} (CVODE {np.max(cv_err):.2e}) wall {wall:.2f} s",
              flush=True)  # fmt: skip
        if ok and np.max(err) <= np.max(cv_err):
            chosen = (tol, err)
            break
    if chosen is None:
        return dict(k=k, members=members, solver=solver, tol=None)
    tol, err = chosen
    sw_wall, sw_cpu = [], []
    cv_walls, cv_cpus = [cv_wall], [cv_cpu]
    for _ in range(repeats):
        _, w, c = common.clock(lambda: run_sweep(tol))
        sw_wall.append(w)
        sw_cpu.append(c)
        _, w, c = common.clock(lambda: _cvode_loop(k, picked, ts, cvode_tol))
        cv_walls.append(w)
        cv_cpus.append(c)
    cv_walls = [w * stride for w in cv_walls]
    cv_cpus = [c * stride for c in cv_cpus]
    return dict(
        k=k, members=members, peer_members=len(picked), device=_device_label(),
        solver=solver, tol=tol, cvode_tol=cvode_tol,
        sweep_max_err_m=float(np.max(err)), cvode_max_err_m=float(np.max(cv_err)),
        sweep_wall_s=min(sw_wall), sweep_cpu_s=min(sw_cpu),
        cvode_wall_s=min(cv_walls), cvode_cpu_s=min(cv_cpus),
        speedup_wall=min(cv_walls) / min(sw_wall),
        speedup_cpu=min(cv_cpus) / min(sw_cpu),
        sweep_compile_s=max(first - min(sw_wall), 0.0), numba_compile_s=numba_s,
        load=os.getloadavg()[0],
    )  # fmt: skip


def main(quick=False, ks=None, members=None, solver="bdf", tols=None,
         cvode_tol=1e-6, repeats=None, group=16, mode="vmap", peer_members=None,
         name=None):  # fmt: skip
    common.set_quick(quick)
    ks = ks or ([8] if quick else [20, 40])
    members = members or (8 if quick else 64)
    peer_members = min(peer_members or members, members)
    if members % peer_members:
        raise ValueError(f"peer_members={peer_members} must divide members={members}")
    tols = tols or [3e-6, 2e-6, 1e-6, 3e-7, 1e-7, 3e-8, 1e-8]
    repeats = repeats or (1 if quick else 2)
    rows = [
        race_k(
            k,
            members,
            solver,
            tols,
            cvode_tol,
            repeats,
            min(group, members),
            mode,
            peer_members,
        )  # fmt: skip
        for k in ks
    ]
    cols = (
        "k members peer_members device solver tol cvode_tol sweep_max_err_m "
        "cvode_max_err_m sweep_wall_s cvode_wall_s speedup_wall sweep_cpu_s "
        "cvode_cpu_s speedup_cpu sweep_compile_s numba_compile_s load"
    ).split()
    peer_note = (
        []
        if peer_members == members
        else [
            f"peer: CVODE-numba ran every {members // peer_members}th member "
            f"({peer_members} runs, one after the other on one CPU core of the same "
            f"machine); its times are scaled by {members // peer_members} to the "
            f"{members} members, and the sweep's error is checked on those members."
        ]
    )
    devices = rows[0].get("device", "-") if rows else "-"
    common.write_table(
        name or "sweep_race",
        rows,
        cols,
        f"{members}-member alpha sweep vs {members} CVODE-numba runs, one process",
        notes=[
            "speedup: CVODE loop time / sweep time (> 1: the sweep is faster); "
            f"minimum over {repeats + 1} CVODE and {repeats} sweep rounds, "
            "interleaved.",
            f"sweep: {mode}, groups of {min(group, members)} sorted by alpha, on "
            f"{devices}; tol: the loosest of the list at which every member's "
            "error is <= CVODE's largest member error.",
            "error: end-mass distance at 0.5, 1, 1.5, 2 s from CVODE-numba at 1e-10.",
            *peer_note,
        ],
    )
    return rows


if __name__ == "__main__":
    common.run_study(
        main,
        lists={"ks": int, "tols": float},
        members=dict(type=int, default=None),
        solver=dict(),
        mode=dict(choices=("lockstep", "vmap")),
        cvode_tol=dict(flag="cvode-tol", type=float, default=1e-6),
        group=dict(type=int, default=16),
        peer_members=dict(flag="peer-members", type=int, default=None),
        name=dict(default=None, help="results name (default sweep_race)"),
    )
