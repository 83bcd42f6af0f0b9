"""Identify the hulls' cross-flow drag coefficients of the tandem from headings.

Question: can `jaxstring.least_squares` recover the cross-flow drag coefficients C_Y
of the FPSO and of the shuttle tanker (spec tanker.md, section 5: 0.52 and 0.55)
from a measured heading time series of both vessels in fishtailing, and are its
standard deviations right?

Scene: `tandem_fishtail` (spec S3a: 1 m/s current from astern of the FPSO, no
thrust, massless hawser), from the aligned equilibrium with the shuttle turned
2.5 deg; the first 3000 s, in which the growing fishtailing swings the shuttle
heading to +6.5 and -12 deg and the FPSO's to -2.5 deg. Data: both headings
every 10 s (301 samples) from Dopri5 at rtol = atol = 1e-11, with 0.1 deg
Gaussian noise. The fit integrates with Tsit5 at rtol = atol = 1e-8 (spec S5:
the tandem is not stiff) and starts 30 % off (FPSO C_Y x 1.3, shuttle C_Y x
0.7); Levenberg-Marquardt on log C_Y with forward-mode Jacobians, tolerance
1e-5. The start state is the measured one: it stays at the true aligned
equilibrium while the coefficients change.

One fit is timed including compilation, then the compiled fit runs on further
noise seeds; the scatter of their estimates is compared with the reported standard
deviations.

Run: ``python experiments/identify_tandem.py [--quick]`` (quick: 3 seeds; full: 12).
Writes results/identify_tandem.{md,csv,png}.
"""

import argparse

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import jaxstring as js
from jaxstring.tandem.scenes import tandem_fishtail


T1, N_SAMPLES, NOISE_DEG = 3000.0, 301, 0.1
PARAMS = ("model.fpso.C_Y", "model.shuttle.C_Y")
START_FACTORS = (1.3, 0.7)
HEADINGS = (2, 8)  # psi1, psi2 in the state


class HeadingResidual(eqx.Module):
    """Model minus measured headings of both vessels, deg."""

    data: jnp.ndarray

    def __call__(self, traj, scene):
        return (jnp.degrees(traj.ys[:, jnp.array(HEADINGS)]) - self.data).ravel()


def measured_headings(scene, ts):
    traj = js.simulate(scene, "dopri5", rtol=1e-11, atol=1e-11, ts=ts, max_steps=10**6)
    return np.degrees(np.asarray(traj.ys)[:, HEADINGS])


def start_scene(truth):
    m = truth.model
    return eqx.tree_at(
        lambda s: (s.model.fpso.C_Y, s.model.shuttle.C_Y),
        truth,
        (m.fpso.C_Y * START_FACTORS[0], m.shuttle.C_Y * START_FACTORS[1]),
    )


def main(quick=False):
    common.set_quick(quick)
    truth = tandem_fishtail(F_ast=0.0, t1=T1)
    true_vals = (float(truth.model.fpso.C_Y), float(truth.model.shuttle.C_Y))
    ts = jnp.linspace(0.0, T1, N_SAMPLES)
    clean = measured_headings(truth, ts)
    start = start_scene(truth)
    n_seeds = 3 if quick else 12
    rows = []
    for seed in range(n_seeds):
        data = clean + NOISE_DEG * np.random.default_rng(seed).standard_normal(
            clean.shape
        )
        res, wall, _ = common.clock(
            lambda: js.least_squares(
                start,
                HeadingResidual(jnp.asarray(data)),
                list(PARAMS),
                ts=ts,
                solver="tsit5",
                rtol=1e-8,
                atol=1e-8,
                tol=1e-5,
                max_steps=100_000,
            )
        )
        true_of = dict(zip(("C_Y1", "C_Y2"), zip(PARAMS, true_vals)))
        rows.append(common.fit_row(seed, res, wall, true_of, "sigma_deg"))
    c1 = np.array([r["C_Y1"] for r in rows])
    c2 = np.array([r["C_Y2"] for r in rows])
    later = float(np.median([r["wall_s"] for r in rows[1:]]))
    notes = [
        f"Truth: C_Y1 (FPSO) = {true_vals[0]}, C_Y2 (shuttle) = {true_vals[1]}; "
        f"start {START_FACTORS[0]}x and {START_FACTORS[1]}x.",
        f"Data: both headings, {N_SAMPLES} samples over {T1:.0f} s of growing "
        f"fishtailing (Dopri5 rtol 1e-11), noise {NOISE_DEG} deg; fit: Tsit5 rtol "
        "1e-8, Levenberg-Marquardt on log C_Y, tolerance 1e-5.",
        f"First fit wall time including compilation: {rows[0]['wall_s']:.1f} s; "
        f"later fits (compiled): median {later:.1f} s.",
        f"Largest error over {n_seeds} seeds: C_Y1 "
        f"{max(abs(r['C_Y1_err_pct']) for r in rows):.2f} %, C_Y2 "
        f"{max(abs(r['C_Y2_err_pct']) for r in rows):.2f} %.",
        f"Scatter of the estimates: C_Y1 {c1.std(ddof=1):.3g}, C_Y2 "
        f"{c2.std(ddof=1):.3g}; mean reported std: C_Y1 "
        f"{np.mean([r['C_Y1_std'] for r in rows]):.3g} (ratio "
        f"{np.mean([r['C_Y1_std'] for r in rows]) / c1.std(ddof=1):.2f}), C_Y2 "
        f"{np.mean([r['C_Y2_std'] for r in rows]):.3g} (ratio "
        f"{np.mean([r['C_Y2_std'] for r in rows]) / c2.std(ddof=1):.2f}).",
    ]
    common.write_table(
        "identify_tandem",
        rows,
        list(rows[0]),
        "Levenberg-Marquardt identification of the hulls' C_Y from headings",
        notes,
    )
    print("\n".join(notes))
    # The figure: seed 0's data, the start and the fitted model.
    fitted = eqx.tree_at(
        lambda s: (s.model.fpso.C_Y, s.model.shuttle.C_Y),
        truth,
        (jnp.asarray(rows[0]["C_Y1"]), jnp.asarray(rows[0]["C_Y2"])),
    )
    model_h = np.degrees(
        np.asarray(js.simulate(fitted, "tsit5", rtol=1e-8, atol=1e-8, ts=ts).ys)[
            :, HEADINGS
        ]
    )
    data0 = clean + NOISE_DEG * np.random.default_rng(0).standard_normal(clean.shape)
    start_h = np.degrees(
        np.asarray(js.simulate(start, "tsit5", rtol=1e-8, atol=1e-8, ts=ts).ys)[
            :, HEADINGS
        ]
    )
    fig, axes = common.new_figure(2, 1, w=4.5, h=3.4)
    for j, (ax, label) in enumerate(zip(axes.ravel(), ("FPSO", "shuttle"))):
        ax.plot(ts, data0[:, j], ".", ms=2, color="0.5", label="data (seed 0)")
        ax.plot(ts, start_h[:, j], "--", lw=0.8, label="start")
        ax.plot(ts, model_h[:, j], lw=1.0, label="fitted")
        ax.set_xlabel("t, s")
        ax.set_ylabel(f"{label} heading, deg")
    axes[0, 0].legend(fontsize=8)
    common.savefig(fig, "identify_tandem")
    return rows


if __name__ == "__main__":
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--quick", action="store_true", help="3 seeds")
    main(quick=cli.parse_args().quick)
