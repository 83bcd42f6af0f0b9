"""A 64-member parameter sweep against a Python loop of 64 simulate calls.

Question: does one compiled sweep agree with the loop (to 1e-10) and how much faster
is it, with plain vmap, grouped members (batch_size, sorted) and two CPU devices?
Goal of issue 7: at least 3x faster than the loop. Run:
python experiments/sweep_speed.py [--quick]. Writes
experiments/results/sweep_speed.{csv,md,png}.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# Two host devices (one per core of this machine); must be set before JAX starts.
os.environ.setdefault("XLA_FLAGS", "--xla_force_host_platform_device_count=2")

import argparse
import statistics
import time

import jax
import matplotlib
import numpy as np


matplotlib.use("Agg")
import matplotlib.pyplot as plt

import jaxstring as js
from jaxstring._sweep import sweep


HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "results")


def fn(traj, scene):
    del scene
    return traj.obs["positions"][:, -1, :]


def main(quick=False, n=64, k=20, t1=1.0, repeats=3):
    if quick:
        n, k, t1, repeats = 8, 6, 0.5, 1
    kw = dict(rtol=1e-8, atol=1e-8, n_save=51)
    alphas = np.linspace(0.005, 0.05, n)
    base = js.scenes.string_pendulum(
        formulation="displacement", k=k, EA=1e4, alpha=0.02, t1=t1
    )

    def loop():
        out = []
        for a in alphas:
            sc = js.scenes.string_pendulum(
                formulation="displacement", k=k, EA=1e4, alpha=a, t1=t1
            )
            out.append(np.asarray(fn(js.simulate(sc, **kw), sc)))
        return np.stack(out)

    t = time.perf_counter()
    ref = loop()
    loop_first = time.perf_counter() - t
    loop_times = []
    for _ in range(repeats):
        t = time.perf_counter()
        ref = loop()
        loop_times.append(time.perf_counter() - t)
    t_loop = statistics.median(loop_times)
    print(
        f"loop of {n} simulate calls: {t_loop:.2f} s "
        f"(first call incl. compile {loop_first:.1f} s)",
        flush=True,
    )
    variants = [
        ("vmap, 1 device", dict(devices=1)),
        (
            "vmap, groups of 8 (sorted), 1 device",
            dict(devices=1, batch_size=8, order="sort"),
        ),
        (f"vmap, {len(jax.devices())} devices", dict()),
        (
            f"groups of 8 (sorted), {len(jax.devices())} devices",
            dict(batch_size=8, order="sort"),
        ),
    ]
    rows = [
        dict(
            variant="python loop",
            time_s=t_loop,
            speedup=1.0,
            max_abs_diff=0.0,
            compile_s=loop_first - t_loop,
        )
    ]
    for name, opts in variants:
        first = sweep(base, {"alpha": alphas}, fn, **opts, **kw)
        times = []
        for _ in range(repeats):
            res = sweep(base, {"alpha": alphas}, fn, **opts, **kw)
            times.append(res.time)
        t_s = statistics.median(times)
        diff = float(np.max(np.abs(res.out - ref)))
        rows.append(
            dict(
                variant=name,
                time_s=t_s,
                speedup=t_loop / t_s,
                max_abs_diff=diff,
                compile_s=first.time - t_s,
            )
        )
        print(
            f"{name:40s} {t_s:.2f} s  speedup {t_loop / t_s:.2f}x  "
            f"max |diff| {diff:.1e}  all ok {bool(res.ok.all())}",
            flush=True,
        )
    steps = res.stats["num_steps"]
    print(
        f"steps per member: min {steps.min()}, median {int(np.median(steps))}, "
        f"max {steps.max()} (lockstep cost ~ max, loop cost ~ sum)"
    )
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "sweep_speed.csv"), "w") as f:
        f.write("variant,time_s,speedup,max_abs_diff,compile_s\n")
        for r in rows:
            f.write(
                f"{r['variant']},{r['time_s']},{r['speedup']},"
                f"{r['max_abs_diff']},{r['compile_s']}\n"
            )
    with open(os.path.join(OUT, "sweep_speed.md"), "w") as f:
        f.write(
            f"{n} members (alpha in [0.005, 0.05]), string pendulum k={k}, "
            f"t1={t1} s, Kvaerno5 rtol=atol=1e-8; medians of {repeats} runs, "
            f"compile excluded; steps per member {steps.min()}..{steps.max()}."
            "\n\n| variant | time s | speedup vs loop | max abs diff |\n"
            "|---|---|---|---|\n"
        )
        for r in rows:
            f.write(
                f"| {r['variant']} | {r['time_s']:.2f} | {r['speedup']:.2f} | "
                f"{r['max_abs_diff']:.1e} |\n"
            )
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.barh([r["variant"] for r in rows], [r["speedup"] for r in rows])
    ax.axvline(3, color="k", ls="--", label="goal: 3x")
    ax.set_xlabel("speedup over a Python loop of simulate calls")
    ax.legend()
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "sweep_speed.png"), dpi=120)
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    main(quick=p.parse_args().quick or bool(os.environ.get("SMOKE_TEST")))
