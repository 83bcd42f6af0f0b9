"""Identification in seconds: Levenberg-Marquardt least squares on a string pendulum.

Question: how fast and how well does `jaxstring.least_squares` recover the damping
alpha and the stiffness EA from noisy end-mass positions, and are its reported
standard deviations right? The data come from an independent implementation of the
displacement-variable string (NumPy right-hand side and analytic Jacobian, scipy's
Radau at rtol 1e-10: `tests/pendulum/test_reference_scipy.py`), k = 16, EA = 1e3 N,
alpha = 0.05 s, l = mu l = m_s = 1, released horizontally, 2 s, 100 samples, with
0.5 mm Gaussian noise on both coordinates. The fit starts 40 % off (alpha = 0.07 s,
EA = 1.4e3 N). One fit is timed including compilation; then 20 noise seeds are
fitted with the compiled fit, and the scatter of their estimates is compared with
the standard deviations each fit reports.

With ``--adam``, the same problem (seed 0) is also fitted with `jaxstring.fit` and
Adam (learning rate 0.05, reverse mode, the same solver settings), counting the
optimiser steps (each one forward and one reverse solve) until both parameters are
within one standard deviation of the least-squares estimate, against the solves
Levenberg-Marquardt made.

Run: ``python experiments/identify_least_squares.py [--quick] [--adam]`` (quick:
4 seeds). Writes results/identify_least_squares.{md,csv,png} (and, with --adam,
identify_least_squares_adam.{md,csv}).
"""

import argparse
import os
import sys

import _common as common
import jax.numpy as jnp
import numpy as np

import jaxstring as js


sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.pendulum.test_reference_scipy import _ReferenceString  # noqa: E402


K, EA, ALPHA, T1, N_SAMPLES, NOISE = 16, 1e3, 0.05, 2.0, 100, 5e-4
START = dict(alpha=0.07, EA=1.4e3)


def reference_end_mass(ts):
    ref = _ReferenceString(K, EA, ALPHA)
    sol = ref.solve(np.asarray(ts))
    return sol.y[2 * K - 2 : 2 * K].T  # the end node's (x, y), (T, 2)


def fit(data, ts):
    start = js.pendulum.string_pendulum(
        "displacement", k=K, EA=START["EA"], alpha=START["alpha"], t1=T1
    )
    res, wall, _ = common.clock(
        lambda: js.least_squares(
            start,
            js.Misfit(jnp.asarray(data)),
            ["alpha", "EA"],
            ts=ts,
            rtol=1e-6,
            atol=1e-6,
            # LM stops when log p changes by less than 1e-5 between steps: a
            # thousandth of the noise's standard deviation of the estimates.
            tol=1e-5,
        )
    )
    return res, wall


def adam_comparison(ts, steps=300):
    """Optimiser steps of `fit` with Adam until alpha and EA both lie within one
    standard deviation of the least-squares estimate (the accuracy the data allow),
    against the solves Levenberg-Marquardt made to get there (seed 0)."""
    clean = reference_end_mass(ts)
    noisy = clean + NOISE * np.random.default_rng(0).standard_normal(clean.shape)
    ls, ls_wall = fit(noisy, ts)
    target = {k: (ls.values[k], ls.std[k]) for k in ("alpha", "EA")}
    data = jnp.asarray(noisy)
    start = js.pendulum.string_pendulum(
        "displacement", k=K, EA=START["EA"], alpha=START["alpha"], t1=T1
    )
    loss = lambda traj, scene: jnp.sum((traj.end_mass - data) ** 2)
    reached = {}

    def callback(step, value, scene):
        now = {"alpha": float(scene.effects[1].alpha), "EA": float(scene.model.EA)}
        if all(abs(now[k] - v) < s for k, (v, s) in target.items()):
            reached["step"] = step + 1
            raise StopIteration

    def run():
        try:
            js.fit(
                start, loss, ["alpha", "EA"], steps=steps, learning_rate=0.05, ts=ts,
                rtol=1e-6, atol=1e-6, print_every=None, callback=callback,
            )  # fmt: skip
        except StopIteration:
            pass

    _, adam_wall, _ = common.clock(run)
    n = reached.get("step")
    row = dict(
        adam_steps=n if n is not None else f"> {steps}",
        adam_solves=2 * n if n is not None else f"> {2 * steps}",
        adam_wall_s=adam_wall,
        lm_iterations=ls.iterations,
        lm_solves=ls.solves,
        lm_wall_s=ls_wall,
        solves_ratio=(2 * (n if n is not None else steps) / ls.solves),
    )
    common.write_table(
        "identify_least_squares_adam",
        [row],
        list(row),
        "Solves to reach the least-squares accuracy: Adam (fit) vs Levenberg-Marquardt",
        [
            "Target: alpha and EA within one reported standard deviation of the "
            "Levenberg-Marquardt estimate (seed 0 of identify_least_squares). Adam: "
            "learning rate 0.05 on log p, one forward and one reverse solve per step; "
            "LM: one forward solve with two JVPs per iteration, plus the start "
            "and the optimum with its Jacobian (one solve with the JVPs). Same "
            "data and solver settings (Kvaerno5, rtol = atol = 1e-6). Wall times "
            "include compilation.",
            "solves_ratio: Adam's solves over LM's (a lower bound where Adam did not "
            "get there within its step budget).",
        ],
    )
    return row


def main(quick=False):
    common.set_quick(quick)
    ts = jnp.linspace(0.0, T1, N_SAMPLES)
    clean = reference_end_mass(ts)
    n_seeds = 4 if quick else 20
    rows = []
    for seed in range(n_seeds):
        rng = np.random.default_rng(seed)
        res, wall = fit(clean + NOISE * rng.standard_normal(clean.shape), ts)
        truth = {"alpha": ("alpha", ALPHA), "EA": ("EA", EA)}
        rows.append(common.fit_row(seed, res, wall, truth, "sigma_m"))
    a = np.array([r["alpha"] for r in rows])
    e = np.array([r["EA"] for r in rows])
    scatter_a, scatter_e = a.std(ddof=1), e.std(ddof=1)
    rep_a = np.mean([r["alpha_std"] for r in rows])
    rep_e = np.mean([r["EA_std"] for r in rows])
    later = np.median([r["wall_s"] for r in rows[1:]]) if len(rows) > 1 else np.nan
    worst_a = np.max(np.abs(a / ALPHA - 1)) * 100
    worst_e = np.max(np.abs(e / EA - 1)) * 100
    notes = [
        f"Data: independent NumPy/scipy Radau implementation, k = {K}, EA = {EA:g} N, "
        f"alpha = {ALPHA} s, {T1} s, {N_SAMPLES} samples, noise {NOISE * 1e3} mm.",
        f"Start 40 % off: alpha = {START['alpha']}, EA = {START['EA']:g}; "
        "Kvaerno5 at rtol = atol = 1e-6, forward-mode Jacobians; LM tolerance 1e-5 "
        "on log p (the estimates' noise std is about 5e-3 in log p).",
        f"First fit (seed 0) wall time including compilation: "
        f"{rows[0]['wall_s']:.1f} s; later fits (compiled): median {later:.1f} s.",
        f"Scatter of the estimates over {n_seeds} seeds: alpha {scatter_a:.3g} s, "
        f"EA {scatter_e:.3g} N; mean reported std: alpha {rep_a:.3g} s (ratio "
        f"{rep_a / scatter_a:.2f}), EA {rep_e:.3g} N (ratio {rep_e / scatter_e:.2f}).",
        f"Largest error over the seeds: alpha {worst_a:.2f} %, EA {worst_e:.2f} %.",
    ]
    columns = list(rows[0])
    common.write_table(
        "identify_least_squares",
        rows,
        columns,
        "Levenberg-Marquardt identification of (alpha, EA), string pendulum k = 16",
        notes,
    )
    fig, axes = common.new_figure(1, 1, w=5.0, h=4.0)
    ax = axes[0, 0]
    ax.errorbar(
        a,
        e,
        xerr=[r["alpha_std"] for r in rows],
        yerr=[r["EA_std"] for r in rows],
        fmt="o",
        ms=3,
        lw=0.6,
        label="fits (reported 1-sigma)",
    )
    ax.plot(ALPHA, EA, "k*", ms=10, label="truth")
    ax.set_xlabel("alpha, s")
    ax.set_ylabel("EA, N")
    ax.legend(fontsize=8)
    common.savefig(fig, "identify_least_squares")
    for n in notes:
        print(n)
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--adam", action="store_true", help="only the Adam comparison")
    a = parser.parse_args()
    if a.adam:
        common.set_quick(a.quick)
        print(adam_comparison(jnp.linspace(0.0, T1, N_SAMPLES)))
    else:
        main(quick=a.quick)
