"""Identify the Kelvin-Voigt constant alpha, and alpha with EA, from noisy positions.

Synthetic measurements: positions of the string's midpoint and end mass from a finer
string (2 k_fit elements) integrated by another solver (Kvaerno3, rtol 1e-10), plus
1 mm Gaussian noise. The fit uses k_fit elements and Kvaerno5, `jaxstring.fit` with
L-BFGS in log parameters and forward-mode derivatives; the uncertainty is the
Gauss-Newton covariance (J^T J / sigma^2)^-1. Run:
python experiments/identify_pendulum.py [--quick]. Writes
experiments/results/identify_pendulum.{csv,md,png}.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse

import equinox as eqx
import jax.numpy as jnp
import matplotlib
import numpy as np
import optax


matplotlib.use("Agg")
import matplotlib.pyplot as plt

import jaxstring as js
from jaxstring import _fit


HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "results")


class Residual(eqx.Module):
    """Model positions minus measured positions at the measured nodes, m."""

    data: jnp.ndarray
    nodes: tuple = eqx.field(static=True)

    def __call__(self, traj, scene):
        del scene
        return traj.obs["positions"][:, list(self.nodes), :] - self.data


def measurements(alpha, EA, k_data, t1, n_t, noise, seed=0):
    scene = js.scenes.string_pendulum(
        formulation="displacement", k=k_data, EA=EA, alpha=alpha, t1=t1
    )
    ts = jnp.linspace(0.0, t1, n_t)
    traj = js.simulate(scene, "kvaerno3", rtol=1e-10, atol=1e-10, ts=ts)
    assert traj.ok, traj.status
    clean = np.asarray(traj.positions[:, [k_data // 2, k_data], :])
    rng = np.random.default_rng(seed)
    return ts, clean, clean + noise * rng.standard_normal(clean.shape)


def main(
    quick=False, alpha=0.02, EA=2e3, k_fit=8, t1=1.5, n_t=151, noise=1e-3, steps=30
):
    if quick:
        k_fit, t1, n_t, steps = 4, 0.6, 61, 15
    k_data = 2 * k_fit
    ts, clean, data = measurements(alpha, EA, k_data, t1, n_t, noise)
    res = Residual(data=jnp.asarray(data), nodes=(k_fit // 2, k_fit))
    loss = lambda traj, scene: jnp.sum(res(traj, scene) ** 2) / noise**2
    rows = []
    fits = {}
    for params, start in [
        (["alpha"], dict(alpha=0.6 * alpha, EA=EA)),
        (["alpha", "EA"], dict(alpha=0.6 * alpha, EA=1.3 * EA)),
    ]:
        scene0 = js.scenes.string_pendulum(
            formulation="displacement", k=k_fit, t1=t1, **start
        )
        r = _fit.fit(
            scene0,
            loss,
            params,
            ts=ts,
            steps=steps,
            optimizer=optax.lbfgs(),
            adjoint="forward",
            print_every=5,
        )
        gn = _fit.gauss_newton(r.scene, res, params, sigma=noise, ts=ts)
        fits[tuple(params)] = r
        truth = {"alpha": alpha, "EA": EA}
        for name, value, std in zip(gn["names"], gn["values"], gn["std"]):
            rows.append(
                dict(
                    fitted="+".join(params),
                    parameter=name,
                    truth=truth[name],
                    value=float(value),
                    std=float(std),
                    rel_error=float(value) / truth[name] - 1,
                    error_in_std=(float(value) - truth[name]) / float(std),
                    chi2_per_residual=r.losses[-1] / data.size,
                    grad_norm=r.grad_norm,
                    steps=len(r.losses),
                    time_s=r.compile_time + r.run_time,
                )
            )
    print(
        "\nfitted      param   truth        value        std        rel.err   err/std"
    )
    for r in rows:
        print(
            f"{r['fitted']:10s}  {r['parameter']:6s}  {r['truth']:.5g}  "
            f"{r['value']:.6g}  {r['std']:.3g}  {r['rel_error']:+.2%}  "
            f"{r['error_in_std']:+.2f}"
        )
    os.makedirs(OUT, exist_ok=True)
    keys = list(rows[0])
    with open(os.path.join(OUT, "identify_pendulum.csv"), "w") as f:
        f.write(",".join(keys) + "\n")
        for r in rows:
            f.write(",".join(str(r[k_]) for k_ in keys) + "\n")
    with open(os.path.join(OUT, "identify_pendulum.md"), "w") as f:
        f.write(
            f"Data: k={k_data}, Kvaerno3 rtol 1e-10, {n_t} times over {t1} s, "
            f"midpoint and end positions, noise {noise * 1e3:.0f} mm. Fit: k="
            f"{k_fit}, Kvaerno5 rtol 1e-8, L-BFGS in log p, forward mode.\n\n"
            "| fitted | parameter | truth | value | GN std | rel. error | "
            "error/std | chi2/residual |\n|---|---|---|---|---|---|---|---|\n"
        )
        for r in rows:
            f.write(
                f"| {r['fitted']} | {r['parameter']} | {r['truth']:.5g} | "
                f"{r['value']:.6g} | {r['std']:.3g} | {r['rel_error']:+.2%} | "
                f"{r['error_in_std']:+.2f} | {r['chi2_per_residual']:.3f} |\n"
            )
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    best = fits[("alpha", "EA")]
    traj = js.simulate(best.scene, ts=ts, rtol=1e-8, atol=1e-8)
    axes[0].plot(ts, data[:, 1, 1], ".", ms=2, label="measured end y (noisy)")
    axes[0].plot(ts, traj.positions[:, k_fit, 1], "-", label="fitted model")
    axes[0].set_xlabel("t (s)")
    axes[0].set_ylabel("y (m)")
    axes[0].legend()
    for key, r in fits.items():
        axes[1].semilogy(r.losses / data.size, label="+".join(key))
    axes[1].set_xlabel("L-BFGS step")
    axes[1].set_ylabel("chi^2 per residual")
    axes[1].legend()
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "identify_pendulum.png"), dpi=120)
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    main(quick=p.parse_args().quick or bool(os.environ.get("SMOKE_TEST")))
