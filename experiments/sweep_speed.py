"""A 64-member parameter sweep against a Python loop of 64 simulate calls.

Goal: a sweep that matches the loop to 1e-10 *and* is at least 3x faster. Case:
string pendulum (displacement variables, k = 20, EA = 1e6 N, t1 = 2 s), 64
Kelvin-Voigt constants alpha in [0.005, 0.05] s. Two settings, each measured
against its own loop, in the same process:

* adaptive (the goal's case): Kvaerno3 at rtol = atol = 1e-6.
  - `lockstep, groups of 4 (sorted)`: the members of a group as one ODE with one
    shared step sequence (per-member error control, batched per-member Newton
    linear algebra): the fastest adaptive sweep, but each member takes other steps
    than its own solve, so it differs from the loop at the tolerance level.
  - `lockstep, groups of 1`: every member its own step sequence inside one
    compiled `lax.map`, with diffrax's PID controller. `simulate`'s Kvaerno default
    is the Newton-limited controller of `jaxstring._solvers.step_size`, so the
    members take other steps than the loop's; `same_steps_as_loop` says whether
    the step counts match (with the PID controller in both they match, and the
    results agree to rounding).
* fixed step: implicit Euler with the paper's step 0.005 s (`implicit_euler_fixed`,
  damped full Newton on the banded Jacobian) and a stage Newton tolerance of 1e-10:
  every member takes the same 400 steps alone and in the sweep, and each step's
  implicit equation is converged far below 1e-10, so sweep and loop agree to
  rounding whatever the grouping.
  - `vmap, groups of 4` / `16`: one solve per member, vmapped in groups (`lax.map`).
    The sweeps compile without XLA:CPU's YNNPACK fusions (`jaxstring._jit`), which
    make groups larger than 4 slower per member.
  - `lockstep, groups of g`: the members' node-major states concatenated along the
    node axis into one state of g k nodes: one banded Newton system per step for
    the whole group (`jaxstring._sweep._FlatBatch`).

Where the time goes (`sweep_speed_profile`): per-call cost of the pieces of one
implicit step for M members at once (vector field, 12 coloured JVPs, banded
Jacobian + block-cyclic-reduction factorisation, solve), jit-compiled inside a
`fori_loop` (no dispatch), next to the cost per member-step of the loop and the
sweeps measured in the main table.

Accuracy: every variant against its loop (max end-mass position difference over
all members and save times), and against a tight reference (Kvaerno5 at rtol =
atol = 1e-10, `simulate`, on the first and last member). Failure isolation: a small
sweep in which one member cannot finish within `max_steps`.

Times: wall-clock and CPU time of this process (the machine is shared: its load is
written into the table notes; the CPU-time ratio is the steadier measure); compile
time separately (first call minus the timed call); all ratios measured in the same
run. Run: nice -n 5 python experiments/sweep_speed.py [--quick]. Writes
experiments/results/sweep_speed.{csv,md,png}, sweep_speed_profile.{csv,md} and
sweep_speed_failure.{csv,md} (--quick: results/quick/, names ending in `_quick`).
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Two CPU devices (the machine's two cores) for the `2 devices` variants; a
# single-device computation (the loop's simulate calls) is unaffected.
if "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    ).strip()

import statistics

import _common as common
import jax
import numpy as np
from _common import (
    clock,
    end_mass_error,
    new_figure,
    savefig,
    set_quick,
    write_table,
)

import jaxstring as js
from jaxstring._sweep import sweep


def end_mass(traj, scene):
    del scene
    return traj.obs["positions"][:, -1, :]


def _scene(k, t1, **kw):
    return js.string_pendulum(formulation="displacement", k=k, t1=t1, **kw)


def _loop(alphas, k, t1, kw):
    out, steps = [], []
    for a in alphas:
        traj = js.simulate(_scene(k, t1, alpha=float(a)), **kw)
        out.append(np.asarray(end_mass(traj, None)))
        steps.append(int(traj.stats["num_steps"]))
    return np.stack(out), np.array(steps)


def failure_demo(k=6, t1=0.5, n=8, tag="", stiff_EA=1e11):
    """One member (EA = `stiff_EA`) cannot finish within `max_steps`; the others
    can. (EA = 1e9 N does not fail: the stage Newton's Jacobian refresh keeps its
    step count under 2x the others'.)"""
    kw = dict(solver="kvaerno3", rtol=1e-6, atol=1e-6, n_save=26)
    alphas = np.linspace(0.005, 0.05, n)
    EAs = np.full(n, 1e4)
    EAs[n // 2] = stiff_EA
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
        f"{n // 2} has EA = {stiff_EA:g} N (the others 1e4 N), max_steps = {max_steps} "
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


def profile(k, Ms, quick):
    """Per-call CPU time of the pieces of one implicit step for M members at once."""
    import jax.numpy as jnp

    from jaxstring._parameters import resolve
    from jaxstring._solvers.stage_newton import batched_factor
    from jaxstring._sweep import _Batch

    reps = 20 if quick else 100
    base = _scene(k, 1.0, alpha=0.01)
    rows = []

    def bench(f, *a):
        g = jax.jit(
            lambda *a: jax.lax.fori_loop(0, reps, lambda i, c: f(*a, c), jnp.zeros(()))
        )
        jax.block_until_ready(g(*a))
        _, _, cpu = clock(lambda: jax.block_until_ready(g(*a)))
        return cpu / reps * 1e6

    for M in Ms:
        batch = _Batch((jnp.linspace(0.005, 0.05, M),), base, (resolve(base, "alpha"),))
        ys = jnp.broadcast_to(base.y0, (M,) + base.y0.shape)
        ys = ys + 1e-3 * jnp.linspace(0, 1, ys.size).reshape(ys.shape)
        res = lambda u, b: u - 1e-3 * b.vector_field(0.0, u)

        def jvps(b, y, c):
            _, lin = jax.linearize(lambda u: res(u, b), y + c)
            seeds = jnp.zeros((12,) + y.shape).at[:, :, 0, 0].set(1.0)
            return c + jnp.sum(jax.vmap(lin)(seeds))

        vf = bench(lambda b, y, c: c + jnp.sum(b.vector_field(0.0, y + c)), batch, ys)
        jv = bench(jvps, batch, ys)
        total = lambda tree: sum(jnp.sum(x) for x in jax.tree_util.tree_leaves(tree))
        fac = bench(lambda b, y, c: c + total(batched_factor(res, y + c, b)), batch, ys)
        F = jax.jit(lambda b, y: batched_factor(res, y, b))(batch, ys)
        sol = bench(lambda f, y, c: c + jnp.sum(f.solve(y + c)), F, ys)
        for piece, us in (
            ("vector field", vf),
            ("12 JVPs (colouring)", jv),
            ("banded Jacobian + BCR factor", fac),
            ("BCR solve", sol),
        ):
            rows.append(dict(M=M, piece=piece, cpu_us=us, cpu_us_per_member=us / M))
        print(
            f"profile M={M}: vf {vf:.1f} jvps {jv:.1f} factor {fac:.1f} "
            f"solve {sol:.1f} us",
            flush=True,
        )
    return rows


def main(quick=False, n=64, k=20, t1=2.0, rounds=3, failure_only=False):
    quick = quick or bool(os.environ.get("SMOKE_TEST"))
    set_quick(quick)
    if failure_only:
        tag = "_quick" if quick else ""
        fail = failure_demo(tag=tag) if quick else failure_demo(k=20, t1=0.5, tag=tag)
        return None, fail
    tag = "_quick" if quick else ""
    load0 = os.getloadavg()
    if quick:
        n, k, t1, rounds = 8, 6, 0.5, 2
    alphas = np.linspace(0.005, 0.05, n)
    base = _scene(k, t1, alpha=0.01)
    values = {"alpha": alphas}

    # Tight reference on the first and last member.
    ref_idx = np.array([0, n - 1])
    ref_kw = dict(solver="kvaerno5", rtol=1e-10, atol=1e-10, n_save=51)
    (ref, _), wall, _ = clock(lambda: _loop(alphas[ref_idx], k, t1, ref_kw))
    print(f"reference ({len(ref_idx)} members) {wall:.0f} s")

    def ref_err(out):
        return max(end_mass_error(out[i], r) for i, r in zip(ref_idx, ref))

    g = 2 if quick else 4
    cases = [
        (
            "adaptive: kvaerno3, rtol=atol=1e-6",
            dict(solver="kvaerno3", rtol=1e-6, atol=1e-6, n_save=51),
            [
                (
                    f"lockstep, groups of {g} (sorted)",
                    dict(mode="lockstep", batch_size=g, order="sort"),
                    "no",
                ),
                ("lockstep, groups of 1", dict(mode="lockstep", batch_size=1), "yes"),
                (
                    "lockstep, groups of 1, 2 devices",
                    dict(mode="lockstep", batch_size=1, devices="auto"),
                    "yes",
                ),
            ],
        ),
        (
            "fixed step: implicit_euler_fixed, dt=0.005 s, Newton tol 1e-10",
            dict(
                solver="implicit_euler_fixed",
                dt0=0.005,
                newton_rtol=1e-10,
                newton_atol=1e-10,
                n_save=51,
            ),
            [
                (f"vmap, groups of {g}", dict(batch_size=g), "yes"),
                (f"vmap, groups of {4 * g}", dict(batch_size=4 * g), "yes"),
                (
                    f"vmap, groups of {4 * g}, 2 devices",
                    dict(batch_size=4 * g, devices="auto"),
                    "yes",
                ),
                ("lockstep, groups of 2", dict(mode="lockstep", batch_size=2), "yes"),
                (
                    f"lockstep, groups of {g}",
                    dict(mode="lockstep", batch_size=g),
                    "yes",
                ),
                (
                    f"lockstep, groups of {2 * g}",
                    dict(mode="lockstep", batch_size=2 * g),
                    "yes",
                ),
            ],
        ),
    ]
    if quick:
        cases[1][2].pop(1)  # groups of 2 = groups of g
    rows = []
    for case, kw, variants in cases:
        calls = [("python loop of simulate", lambda kw=kw: _loop(alphas, k, t1, kw))]
        for name, opts, _ in variants:
            calls.append(
                (
                    name,
                    lambda o=opts, kw=kw: sweep(
                        base, values, end_mass, **{"devices": 1, **o}, **kw
                    ),
                )
            )
        # First (compiling) call of each, then `rounds` rounds timing the loop and
        # every variant in turn: the load of this shared machine changes within
        # minutes, and interleaving exposes every variant to the same changes.
        firsts, outs = [], []
        for name, call in calls:
            out, wall, _ = clock(call)
            outs.append(out)
            firsts.append(wall)
        walls = [[] for _ in calls]
        cpus = [[] for _ in calls]
        for r in range(rounds):
            for j, (name, call) in enumerate(calls):
                _, wall, cpu = clock(call)
                walls[j].append(wall)
                cpus[j].append(cpu)
            print(
                f"{case} round {r}: "
                + ", ".join(
                    f"{nm} {w[-1]:.1f}/{c[-1]:.1f} s"
                    for (nm, _), w, c in zip(calls, walls, cpus)
                ),
                flush=True,
            )
        loop_out, loop_steps = outs[0]
        med = statistics.median
        for j, (name, _) in enumerate(calls):
            if j == 0:
                out, ok = loop_out, True
                steps = (
                    f"{loop_steps.min()}..{loop_steps.max()} (sum {loop_steps.sum()})"
                )
                identical = "-"
            else:
                res = outs[j]
                out = res.out
                opts = variants[j - 1][1]
                ok = bool(res.ok.all()) and res.mode == opts.get("mode", "vmap")
                st = res.stats["num_steps"]
                steps = f"{st.min()}..{st.max()}"
                # Same steps as the loop: per-member step counts equal (groups of 1,
                # vmap, fixed step) -- a check, not a claim (a lockstep group of 1
                # uses the PID controller; simulate's default controller may differ).
                same = np.array_equal(np.asarray(st), loop_steps)
                identical = "yes" if same else "no"
            sw = [a / b for a, b in zip(walls[0], walls[j])]
            sc = [a / b for a, b in zip(cpus[0], cpus[j])]
            diff = float(np.max(np.abs(out - loop_out)))
            row = dict(
                case=case,
                variant=name,
                steps=steps,
                same_steps_as_loop=identical,
                wall_s=med(walls[j]),
                cpu_s=med(cpus[j]),
                speedup_wall=med(sw),
                speedup_cpu=med(sc),
                range_wall=f"{min(sw):.2f}..{max(sw):.2f}",
                range_cpu=f"{min(sc):.2f}..{max(sc):.2f}",
                compile_s=max(firsts[j] - med(walls[j]), 0.0),
                rounds=rounds,
                diff_vs_loop=diff,
                err_vs_ref=ref_err(out),
                all_ok=ok,
                meets_goal="-"
                if j == 0
                else bool(ok and diff <= 1e-10 and med(sw) >= 3),
            )
            rows.append(row)
            print(
                f"  {name:35s} {row['wall_s']:.1f} s ({row['speedup_wall']:.2f}x wall, "
                f"{row['speedup_cpu']:.2f}x CPU), compile {row['compile_s']:.0f} s, "
                f"|diff| {diff:.1e}, err {row['err_vs_ref']:.1e}",
                flush=True,
            )
    load1 = os.getloadavg()
    cols = (
        "case variant steps same_steps_as_loop wall_s cpu_s speedup_wall "
        "speedup_cpu range_wall range_cpu compile_s rounds diff_vs_loop "
        "err_vs_ref all_ok meets_goal"
    ).split()
    load = (
        f"load average (1, 5, 15 min) at start {load0[0]:.1f}, {load0[1]:.1f}, "
        f"{load0[2]:.1f}; at end {load1[0]:.1f}, {load1[1]:.1f}, {load1[2]:.1f} "
        f"({os.cpu_count()} cores, other users' JAX processes running)"
    )
    write_table(
        f"sweep_speed{tag}",
        rows,
        cols,
        f"{n} members (alpha in [0.005, 0.05] s), string pendulum k={k}, "
        f"EA=1e6 N, t1={t1} s, 51 save times, 1 device unless stated",
        notes=[
            "wall_s / cpu_s: medians over `rounds` rounds, each timing the loop and "
            "every variant in turn (after a first, compiling call of each); "
            "speedup = median over the rounds of loop / variant in the same round "
            "(range: smallest..largest round); compile_s = first call - median.",
            "steps: steps per member (loop, vmap, groups of 1) or of the shared step "
            "sequences (lockstep groups). same_steps_as_loop: every member takes "
            "exactly its own simulate call's steps.",
            "diff_vs_loop: max |end-mass position difference| against the loop (m) "
            "over all members and save times; err_vs_ref: max end-mass distance to "
            f"Kvaerno5 at rtol=atol=1e-10 on members {ref_idx.tolist()} (m).",
            "meets_goal: diff_vs_loop <= 1e-10 and wall-clock speedup "
            ">= 3, all members ok. The CPU-time ratio is the work saved. `2 "
            "devices`: the members split over two CPU devices, whose shards "
            "XLA:CPU runs one after the other (each dispatched from the calling "
            "thread).",
            load,
        ],
    )
    prof = profile(k, (1, 4) if quick else (1, 4, 16, 64), quick)
    write_table(
        f"sweep_speed_profile{tag}",
        prof,
        ["M", "piece", "cpu_us", "cpu_us_per_member"],
        f"Pieces of one implicit step for M members at once (string pendulum k={k}, "
        "displacement, state 20 x 4 per member): CPU microseconds per call, "
        "jit-compiled, repeated in a fori_loop",
        notes=[
            "Kvaerno3 (chord Newton) does per step about 1 factorisation (more with "
            "Jacobian refreshes), 3 implicit stages of 2-4 iterations (vector field + "
            "solve each); the fixed-step implicit Euler's full Newton one "
            "factorisation per iteration (2-4 per step).",
            "A step of the loop costs about 100-160 us of CPU for 17-40 us of these "
            "pieces: the rest is the solver loop's per-iteration overhead, which a "
            "lockstep group shares between its members; the factorisation's cost per "
            "member grows with M (more memory traffic per block).",
            "These pieces are compiled with JAX's default options (YNNPACK fusions "
            "on); the sweeps compile without them (see the module docstring).",
            load,
        ],
    )
    fig, axes = new_figure(1, 1, w=8.0, h=0.45 * len(rows) + 1.2)
    ax = axes[0, 0]
    labels = [f"{r['case'].split(':')[0]}: {r['variant']}" for r in rows]
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
    common.run_study(
        main,
        failure_only=dict(
            flag="failure-only",
            action="store_true",
            help="only the failure-isolation table (sweep_speed_failure.*)",
        ),
    )
