"""Cost of a gradient (d loss / d (alpha, EA)) relative to the forward solve.

Question: how many forward solves does one gradient cost, per formulation and
adjoint? Target: at most 5x. Run: python experiments/gradient_cost.py
[--quick]. Writes experiments/results/gradient_cost.{csv,md,png}.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import statistics

import equinox as eqx
import jax
import jax.numpy as jnp
import matplotlib


matplotlib.use("Agg")
import matplotlib.pyplot as plt
from _common import clock, results_file, savefig, set_quick, stamp_markdown

import jaxstring as js
from jaxstring import _fit


def loss_fn(traj, scene):
    del scene
    return jnp.sum(traj.obs["positions"][:, -1, :] ** 2) + 1e3 * jnp.max(
        traj.obs["strain"]
    )


def timed(f, repeats):
    _, first, _ = clock(lambda: jax.block_until_ready(f()))
    runs = [clock(lambda: jax.block_until_ready(f()))[1] for _ in range(repeats)]
    return first, statistics.median(runs)


def main(quick=False, k=20, t1=1.0, repeats=5):
    set_quick(quick)
    if quick:
        k, t1, repeats = 8, 0.5, 3
    rows = []
    formulations = ("displacement",) if quick else ("displacement", "natural", "angle")
    adjoints = (("forward", None), ("recursive", "auto"), ("recursive", None))
    for form in formulations:
        scene = js.string_pendulum(formulation=form, k=k, EA=1e4, alpha=0.02, t1=t1)
        cfg = _fit.SolveConfig(rtol=1e-8, atol=1e-8, n_save=101)
        fwd = eqx.filter_jit(lambda s: loss_fn(_fit.solve(s, cfg), s))
        c_f, t_f = timed(lambda: fwd(scene), repeats)
        steps = int(_fit.solve(scene, cfg).stats["num_steps"])
        for adj, ck in adjoints:
            label = adj + (
                ""
                if ck is None and adj == "forward"
                else f" (checkpoints={ck or 'diffrax default'})"
            )
            # Same compiled step as `fit` uses (one filter_jit of value and gradient).
            _, theta, pos, frozen, config, ts = _fit._setup(
                scene,
                loss_fn,
                ["alpha", "EA"],
                False,
                True,
                None,
                adj,
                ck,
                dict(rtol=1e-8, atol=1e-8, n_save=101),
            )
            g = lambda: _fit._jit_value_and_grad(
                theta, pos, frozen, loss_fn, config, True, ts
            )
            c_g, t_g = timed(g, repeats)
            rows.append(
                dict(
                    formulation=form,
                    adjoint=label,
                    k=k,
                    steps=steps,
                    forward_s=t_f,
                    grad_s=t_g,
                    ratio=t_g / t_f,
                    compile_forward_s=c_f - t_f,
                    compile_grad_s=c_g - t_g,
                )
            )
            print(
                f"{form:12s} {label:40s} forward {t_f:.3f} s  grad {t_g:.3f} s  "
                f"ratio {t_g / t_f:.2f}  (compile {c_g - t_g:.1f} s)",
                flush=True,
            )
    keys = list(rows[0])
    with results_file("gradient_cost.csv") as f:
        f.write(",".join(keys) + "\n")
        for r in rows:
            f.write(",".join(str(r[k_]) for k_ in keys) + "\n")
    with results_file("gradient_cost.md") as f:
        f.write(
            "# Cost of a gradient relative to the forward solve\n\n"
            + stamp_markdown()
            + "\n\n"
            f"Gradient of a loss w.r.t. (alpha, EA), string pendulum k={k}, "
            f"t1={t1} s, Kvaerno5 rtol=atol=1e-8; medians of {repeats} runs, "
            "compile excluded.\n\n| formulation | adjoint | steps | forward s | "
            "gradient s | ratio |\n|---|---|---|---|---|---|\n"
        )
        for r in rows:
            f.write(
                f"| {r['formulation']} | {r['adjoint']} | {r['steps']} | "
                f"{r['forward_s']:.3f} | {r['grad_s']:.3f} | {r['ratio']:.2f} |\n"
            )
    fig, ax = plt.subplots(figsize=(8, 4))
    labels = [f"{r['formulation']}\n{r['adjoint']}" for r in rows]
    ax.bar(range(len(rows)), [r["ratio"] for r in rows])
    ax.axhline(5, color="k", ls="--", label="goal: 5x")
    ax.set_xticks(range(len(rows)), labels, fontsize=6, rotation=30, ha="right")
    ax.set_ylabel("gradient time / forward time")
    ax.legend()
    fig.tight_layout()
    savefig(fig, "gradient_cost", dpi=120, tight=False)
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    main(quick=p.parse_args().quick or bool(os.environ.get("SMOKE_TEST")))
