"""A 64-member parameter sweep against a Python loop of 64 simulate calls (issue 7).

Question: how much faster than a loop of `simulate` calls is one compiled sweep, and
how accurate is it? Case of the issue: string pendulum (displacement variables,
k = 20, EA = 1e6 N, default t1 = 2 s), 64 Kelvin-Voigt constants alpha in
[0.005, 0.05] s, Kvaerno3 and Kvaerno5 at rtol = atol = 1e-6. Variants:

* `vmap`: one vmapped solve per member (`sweep(mode="vmap")`): equal to the loop to
  rounding, but a vmapped adaptive solve runs its members in lockstep *inside* a
  masked loop, and every `lax.cond` of the solver (Jacobian refresh, step
  rejection) becomes "compute both branches".
* `lockstep`: all members as one ODE on the stacked state (`mode="lockstep"`): one
  shared step sequence, accepted when every member's own error norm is within the
  tolerance; block-diagonal Newton linear algebra (per-member banded Jacobians from
  12 JVPs of the stacked vector field, vmapped block cyclic reduction).
* groups: lockstep in consecutive groups of 16 members sorted by alpha (each group
  its own step sequence); 2 devices: the members split over two host devices
  (``--xla_force_host_platform_device_count=2``, set below before JAX starts), one
  per core, each running its own solve.

Accuracy: every variant against the loop (max end-mass distance over all members and
save times), and the loop and every variant against a tight reference (Kvaerno5 at
rtol = atol = 1e-10, one `simulate` call per member, on `n_ref` members spread over
the range). Failure isolation: a small sweep in which one member cannot finish
within `max_steps`.

Times: wall-clock medians (this 2-core machine is shared, so also the CPU time of
the process, which other users' load inflates less); compile time separately (first
call minus the median); all ratios measured in the same run.
Run: python experiments/sweep_speed.py [--quick]. Writes
experiments/results/sweep_speed{,_quick}.{csv,md,png} and sweep_speed_failure*.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Two host devices (one per core of this machine); must be set before JAX starts.
os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")

import argparse
import statistics
import time

import jax
import numpy as np
from _common import end_mass_error, new_figure, savefig, write_table

import jaxstring as js
from jaxstring._sweep import sweep


LONG_RUN_S = 20.0  # a run longer than this is timed once (after the compile call)


def end_mass(traj, scene):
    del scene
    return traj.obs["positions"][:, -1, :]


def _scene(k, t1, **kw):
    return js.scenes.string_pendulum(formulation="displacement", k=k, t1=t1, **kw)


def _timed(call, repeats):
    """(first wall s, median wall s, median CPU s, last result) of `call()`."""
    t, c = time.perf_counter(), time.process_time()
    out = call()
    first = time.perf_counter() - t
    walls, cpus = [], []
    for i in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        out = call()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
        if i == 0 and walls[0] > LONG_RUN_S:
            break
    return first, statistics.median(walls), statistics.median(cpus), out, len(walls)


def _loop(alphas, k, t1, kw):
    out, steps = [], []
    for a in alphas:
        traj = js.simulate(_scene(k, t1, alpha=float(a)), **kw)
        out.append(np.asarray(end_mass(traj, None)))
        steps.append(int(traj.stats["num_steps"]))
    return np.stack(out), np.array(steps)


def failure_demo(k=6, t1=0.5, n=8, tag=""):
    """One member (EA = 1e9 N) cannot finish within `max_steps`; the others can."""
    kw = dict(solver="kvaerno3", rtol=1e-6, atol=1e-6, n_save=26)
    alphas = np.linspace(0.005, 0.05, n)
    EAs = np.full(n, 1e4)
    EAs[n // 2] = 1e9
    base = _scene(k, t1, EA=1e4, alpha=0.01)
    refs, steps = [], []
    for a, ea in zip(alphas, EAs):
        if ea > 1e4:
            refs.append(None)
            continue
        traj = js.simulate(_scene(k, t1, EA=ea, alpha=a), **kw)
        refs.append(np.asarray(traj.end_mass))
        steps.append(int(traj.stats["num_steps"]))
    max_steps = int(2 * max(steps))
    rows = []
    for mode in ("vmap", "lockstep"):
        res = sweep(
            base,
            {"alpha": alphas, "EA": EAs},
            end_mass,
            devices=1,
            mode=mode,
            max_steps=max_steps,
            **kw,
        )
        diff = max(
            float(np.max(np.abs(res.out[i] - refs[i])))
            for i in range(n)
            if refs[i] is not None
        )
        rows.append(
            dict(
                mode=mode,
                ran_as=res.mode,
                ok=" ".join("T" if o else "F" for o in res.ok),
                failed_status=res.status[n // 2],
                others_vs_loop=diff,
                time_s=res.time,
            )
        )
    write_table(
        f"sweep_speed_failure{tag}",
        rows,
        ["mode", "ran_as", "ok", "failed_status", "others_vs_loop", "time_s"],
        f"Failure isolation: {n} members, k={k}, t1={t1} s, Kvaerno3 1e-6, member "
        f"{n // 2} has EA = 1e9 N (the others 1e4 N), max_steps = {max_steps} "
        "(2x the most any other member needs)",
        notes=[
            "others_vs_loop: max |end-mass difference| of the successful members "
            "against their own simulate calls (m).",
            "lockstep: the shared solve stops when one member cannot go on; "
            "sweep then re-runs the members one solve each (fallback=True), so every "
            "member gets its own status. time_s includes compilation.",
        ],
    )
    return rows


def main(quick=False, n=64, k=20, t1=2.0, solvers=("kvaerno3", "kvaerno5"), repeats=3):
    tag = "_quick" if quick else ""
    n_ref = 4
    if quick:
        n, k, t1, solvers, repeats, n_ref = 8, 6, 0.5, ("kvaerno3",), 1, 2
    alphas = np.linspace(0.005, 0.05, n)
    base = _scene(k, t1, alpha=0.01)
    values = {"alpha": alphas}
    n_dev = len(jax.devices())

    # Tight reference on n_ref members spread over the range.
    ref_idx = np.unique(np.linspace(0, n - 1, n_ref).round().astype(int))
    ref_kw = dict(solver="kvaerno5", rtol=1e-10, atol=1e-10, n_save=51)
    t = time.perf_counter()
    ref, _ = _loop(alphas[ref_idx], k, t1, ref_kw)
    print(f"reference ({len(ref_idx)} members) {time.perf_counter() - t:.0f} s")

    def ref_err(out):
        return max(end_mass_error(out[i], r) for i, r in zip(ref_idx, ref))

    rows = []
    for solver in solvers:
        kw = dict(solver=solver, rtol=1e-6, atol=1e-6, n_save=51)
        first, wall, cpu, (loop_out, loop_steps), reps = _timed(
            lambda: _loop(alphas, k, t1, kw), repeats
        )
        print(f"{solver} loop: {wall:.1f} s wall, {cpu:.1f} s CPU", flush=True)
        rows.append(
            dict(
                solver=solver,
                variant="python loop of simulate",
                wall_s=wall,
                cpu_s=cpu,
                speedup_wall=1.0,
                speedup_cpu=1.0,
                compile_s=max(first - wall, 0.0),
                repeats=reps,
                steps=f"{loop_steps.min()}..{loop_steps.max()} "
                f"(sum {loop_steps.sum()})",
                diff_vs_loop=0.0,
                err_vs_ref=ref_err(loop_out),
                all_ok=True,
            )
        )
        t_loop, c_loop = wall, cpu
        variants = [
            ("vmap, 1 device", dict(devices=1)),
            ("lockstep, 1 device", dict(devices=1, mode="lockstep")),
            (
                f"lockstep, {n_dev} devices",
                dict(mode="lockstep"),
            ),
        ]
        if solver == solvers[0]:
            for g in (4,) if quick else (16, 8):
                variants.append(
                    (
                        f"lockstep, groups of {g} (sorted), 1 device",
                        dict(devices=1, mode="lockstep", batch_size=g, order="sort"),
                    )
                )
            g = 4 if quick else 8
            variants.append(
                (
                    f"lockstep, groups of {g} (sorted), {n_dev} devices",
                    dict(mode="lockstep", batch_size=g, order="sort"),
                )
            )
        if quick:
            # (vmap over 2 devices: 0.7-0.8x of the loop in earlier full runs; only
            # in the quick run, to keep the full run within ~45 min here.)
            variants.append((f"vmap, {n_dev} devices", dict()))
        for name, opts in variants:
            first, wall, cpu, res, reps = _timed(
                lambda: sweep(base, values, end_mass, **opts, **kw), repeats
            )
            steps = res.stats["num_steps"]
            row = dict(
                solver=solver,
                variant=name,
                wall_s=wall,
                cpu_s=cpu,
                speedup_wall=t_loop / wall,
                speedup_cpu=c_loop / cpu,
                compile_s=max(first - wall, 0.0),
                repeats=reps,
                steps=f"{steps.min()}..{steps.max()}",
                diff_vs_loop=float(np.max(np.abs(res.out - loop_out))),
                err_vs_ref=ref_err(res.out),
                all_ok=bool(res.ok.all()),
            )
            rows.append(row)
            print(
                f"{solver} {name:45s} {wall:.1f} s ({t_loop / wall:.2f}x wall, "
                f"{c_loop / cpu:.2f}x CPU), compile {row['compile_s']:.0f} s, "
                f"|diff| {row['diff_vs_loop']:.1e}, err {row['err_vs_ref']:.1e}",
                flush=True,
            )
    cols = [
        "solver",
        "variant",
        "wall_s",
        "cpu_s",
        "speedup_wall",
        "speedup_cpu",
        "compile_s",
        "repeats",
        "steps",
        "diff_vs_loop",
        "err_vs_ref",
        "all_ok",
    ]
    write_table(
        f"sweep_speed{tag}",
        rows,
        cols,
        f"{n} members (alpha in [0.005, 0.05] s), string pendulum k={k}, "
        f"EA=1e6 N, t1={t1} s, rtol=atol=1e-6, 51 save times",
        notes=[
            "wall_s / cpu_s: medians of `repeats` runs after a first (compiling) "
            "call; compile_s = first call - median. speedup = loop / variant, "
            "measured in the same process.",
            "steps: steps per member (loop, vmap) or of the shared step sequence "
            "(lockstep: all members of a device or group take the same steps).",
            "diff_vs_loop: max |end-mass position difference| against the loop (m) "
            "over all members and save times; err_vs_ref: max end-mass distance "
            f"to Kvaerno5 at rtol=atol=1e-10 on members {ref_idx.tolist()} (m).",
            "The machine's other users load its 2 cores unevenly; cpu_s (this "
            "process's CPU time) is the steadier measure of work.",
        ],
    )
    fig, axes = new_figure(1, 1, w=8.0, h=0.45 * len(rows) + 1.2)
    ax = axes[0, 0]
    labels = [f"{r['solver']}: {r['variant']}" for r in rows]
    y = np.arange(len(rows))
    ax.barh(y - 0.2, [r["speedup_wall"] for r in rows], height=0.4, label="wall")
    ax.barh(y + 0.2, [r["speedup_cpu"] for r in rows], height=0.4, label="CPU")
    ax.set_yticks(y, labels)
    ax.invert_yaxis()
    ax.axvline(3, color="k", ls="--", lw=1, label="goal: 3x")
    ax.set_xlabel("speed-up over a Python loop of simulate calls")
    ax.legend()
    savefig(fig, f"sweep_speed{tag}")
    fail = failure_demo(tag=tag) if quick else failure_demo(k=20, t1=0.5, tag=tag)
    return rows, fail


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    p.add_argument("--solvers", default="kvaerno3,kvaerno5")
    a = p.parse_args()
    main(
        quick=a.quick or bool(os.environ.get("SMOKE_TEST")),
        solvers=tuple(a.solvers.split(",")),
    )
