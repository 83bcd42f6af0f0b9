"""Identify the tether's normal drag coefficient c_n from the running-end force in a
current (spec tether.md, Blintsov 2017 Table 1 tether).

Synthetic measurement: the running-end force (3 components, N) of a short scenario of
the exact-tension tether (`tether_fixed(method="exact")`, L = 100 m, current 1 m/s
toward -x, c_n = 1, c_t = 0.1): the line settles from its initial arc for `t_hold` s,
then the running end is towed forward (+x, against the current) at 1 m/s (1 s
velocity ramps). The data chain has `N_data` = 2 `N_fit` elements and is integrated at
rtol = atol = 1e-10; Gaussian noise of `noise` N is added to every component.

Fit: the coarser chain (`N_fit` elements, Dopri5 rtol = atol = 1e-8), c_n in log space
by L-BFGS with forward-mode derivatives (`jaxstring._fit.fit`), starting 30 % low;
uncertainty from the Gauss-Newton covariance (J^T J / sigma^2)^-1
(`jaxstring._fit.gauss_newton`). The discretisation bias (N_fit vs N_data) is
reported next to the statistical error.

    python experiments/identify_tether.py [--quick]

Writes results/identify_tether.{md,csv,png}.

With ``--least-squares``: both drag coefficients (c_n, c_t) by `jaxstring.least_squares`
(Levenberg-Marquardt, forward-mode Jacobians) from a start 30 % low on the same data,
with N_fit = 40 elements, against `jaxstring.fit` with Adam (learning rate 0.05,
reverse mode) counting the solves until both coefficients lie within one reported
standard deviation of the least-squares estimate. Writes
results/identify_tether_least_squares.{md,csv}.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse

import _common as C
import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax

import jaxstring as js
from jaxstring import _fit
from jaxstring.tether.scenes import tether_fixed


T_HOLD, T_TOW = 10.0, 10.0


def scenario(N, c_n=1.0, t_hold=T_HOLD, t_tow=T_TOW, speed=1.0):
    """The short identification scenario with `N` elements and drag coefficient c_n."""
    t1 = t_hold + t_tow
    start = (0.0, 0.0, -50.0)
    end = (speed * t_tow, 0.0, -50.0)
    return tether_fixed(
        method="exact",
        N=N,
        c_n=c_n,
        t1=t1,
        times=(0.0, t_hold, t1),
        fast_path=(start, start, end),
        smoothing=1.0,
    )


def fit_window(ts):
    """1 at the samples used in the fit: the steady tow, after the 1 s velocity ramp
    and before the stop (the settling from the initial arc, released at rest, is the
    part of the record most sensitive to the chain's discretisation)."""
    t = np.asarray(ts)
    return ((t >= T_HOLD + 1.0) & (t <= T_HOLD + T_TOW - 1.0)).astype(float)


class EndForceResidual(eqx.Module):
    """Model running-end force minus the measured one at the save times, N, times
    the 0/1 `weight` of each time."""

    data: jnp.ndarray
    weight: jnp.ndarray

    def __call__(self, traj, scene):
        del scene
        return (traj.obs["fast_force"] - self.data) * self.weight[:, None]


def measurement(N_data, ts, noise, c_n=1.0, seed=0):
    scene = scenario(N_data, c_n=c_n)
    traj = js.simulate(scene, "dopri5", rtol=1e-10, atol=1e-10, ts=ts, max_steps=10**6)
    if not traj.ok:
        raise RuntimeError(f"data run failed: {traj.status}")
    clean = np.asarray(traj.fast_force)
    rng = np.random.default_rng(seed)
    return clean, clean + noise * rng.standard_normal(clean.shape)


def identify(N_fit, ts, data, noise, c_n0, steps=12, print_every=2):
    res = EndForceResidual(data=jnp.asarray(data), weight=jnp.asarray(fit_window(ts)))
    loss = lambda traj, scene: jnp.sum(res(traj, scene) ** 2) / noise**2
    scene0 = scenario(N_fit, c_n=c_n0)
    kw = dict(solver="dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=100_000)
    r = _fit.fit(
        scene0,
        loss,
        ["Cd"],
        steps=steps,
        optimizer=optax.lbfgs(),
        adjoint="forward",
        print_every=print_every,
        **kw,
    )
    gn, gn_s, _ = C.clock(
        lambda: _fit.gauss_newton(r.scene, res, ["Cd"], sigma=noise, **kw)
    )
    return r, gn, gn_s


def main(quick=False, c_n=1.0, noise=1.0):
    """Identify c_n (truth `c_n`) from end forces with Gaussian noise `noise` N."""
    C.set_quick(quick)
    sfx = "_quick" if quick else ""
    # The end force converges like 1/N (tow-phase Fx: -169, -187, -198, -204 N at
    # N = 10, 20, 40, 80), and c_n absorbs about twice the relative force error:
    # a fit chain of 10 vs 20 elements gives c_n 19 % high.
    N_fit = 40 if quick else 80
    N_data = 2 * N_fit
    t1 = float(scenario(4).t1)
    ts = jnp.linspace(0.0, t1, 81)
    clean, data = measurement(N_data, ts, noise, c_n=c_n)
    r, gn, gn_s = identify(N_fit, ts, data, noise, 0.7 * c_n, steps=8 if quick else 12)
    value, std = float(gn["values"][0]), float(gn["std"][0])
    # Discretisation bias: the coarse chain with the true c_n against the clean data.
    sc = scenario(N_fit, c_n=c_n)
    coarse = js.simulate(sc, "dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6)
    w = fit_window(ts)
    n_used = int(w.sum()) * data.shape[1]
    diff = (np.asarray(coarse.fast_force) - clean) * w[:, None]
    model_err = float(np.sqrt(np.sum(diff**2) / n_used))
    chi2 = float(r.losses[np.nanargmin(r.losses)]) / n_used
    rows = [
        dict(
            N_data=N_data,
            N_fit=N_fit,
            noise_N=noise,
            c_n_true=c_n,
            c_n_start=0.7 * c_n,
            c_n_fit=value,
            gn_std=std,
            rel_error=value / c_n - 1,
            error_in_std=(value - c_n) / std,
            chi2_per_residual=chi2,
            model_rms_N=model_err,
            force_rms_N=float(np.sqrt(np.sum((clean * w[:, None]) ** 2) / n_used)),
            steps=len(r.losses),
            compile_s=r.compile_time,
            run_s=r.run_time,
            gn_s=gn_s,
        )
    ]
    notes = [
        f"scenario: {t1:g} s, hold {T_HOLD:g} s then tow the running end +x at 1 m/s "
        f"against a 1 m/s current; {ts.size} samples of the 3 end-force components, "
        f"those in [{T_HOLD + 1:g}, {t1 - 1:g}] s fitted ({n_used} residuals); "
        f"data chain N = {N_data} at rtol 1e-10, fit chain N = {N_fit} at rtol 1e-8",
        "model_rms_N: rms difference of the coarse chain's end force (true c_n) from "
        "the clean data over the fit window (discretisation error, not noise); "
        "force_rms_N: rms of the clean data there",
        f"|rel_error| < 5 %: {abs(value / c_n - 1) < 0.05}",
    ]
    # Convergence of the tow-phase end force with the number of elements (true c_n).
    conv = []
    for N in (N_fit // 4, N_fit // 2, N_fit, N_data):
        tr = js.simulate(
            scenario(N, c_n=c_n), "dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6
        )
        conv.append((N, float(np.mean(np.asarray(tr.fast_force)[w > 0, 0]))))
    notes.append(
        "mean tow-phase F_x (N) vs elements N: "
        + ", ".join(f"N={n}: {f:.2f}" for n, f in conv)
    )
    C.write_table(
        f"identify_tether{sfx}",
        rows,
        list(rows[0]),
        "Tether: c_n from the running-end force (finer data chain, coarser fit chain)",
        notes,
    )
    fit_traj = js.simulate(
        r.scene, "dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6
    )
    fig, ax = C.new_figure(ncols=2, w=5.0, h=3.6)
    t = np.asarray(ts)
    for j, lab in enumerate("xyz"):
        if np.max(np.abs(clean[:, j])) < 1e-6:
            continue
        ax[0, 0].plot(t, data[:, j], ".", ms=3, color=f"C{j}", label=f"data F{lab}")
        ax[0, 0].plot(t, np.asarray(fit_traj.fast_force)[:, j], "-", color=f"C{j}")
    ax[0, 0].set_xlabel("t (s)")
    ax[0, 0].set_ylabel("running-end force (N)")
    ax[0, 0].legend(fontsize=7)
    ax[0, 1].plot(r.params["Cd"], "o-")
    ax[0, 1].axhline(c_n, color="k", ls=":")
    ax[0, 1].set_xlabel("L-BFGS step")
    ax[0, 1].set_ylabel("c_n")
    fig.suptitle(f"c_n = {value:.4f} +- {std:.4f} (truth {c_n:g})")
    C.savefig(fig, f"identify_tether{sfx}")
    return rows


def least_squares_vs_adam(N_fit=40, noise=1.0, adam_steps=600):
    """(c_n, c_t) by Levenberg-Marquardt, and the solves Adam needs for the same
    accuracy."""
    t1 = float(scenario(4).t1)
    ts = jnp.linspace(0.0, t1, 81)
    truth = dict(Cd=1.0, CdAx=float(scenario(4).effects[2].CdAx))
    _, data = measurement(2 * N_fit, ts, noise)
    res = EndForceResidual(data=jnp.asarray(data), weight=jnp.asarray(fit_window(ts)))
    start = scenario(N_fit, c_n=0.7)
    start = eqx.tree_at(lambda s: s.effects[2].CdAx, start, 0.7 * start.effects[2].CdAx)
    kw = dict(solver="dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=100_000)
    ls, ls_wall, _ = C.clock(
        lambda: js.least_squares(start, res, ["Cd", "CdAx"], sigma=noise, **kw)
    )
    target = {k: (ls.values[k], ls.std[k]) for k in ("Cd", "CdAx")}
    reached = {}

    def callback(step, value, scene):
        drag = scene.effects[2]
        now = {"Cd": float(drag.Cd), "CdAx": float(drag.CdAx)}
        if all(abs(now[k] - v) < sd for k, (v, sd) in target.items()):
            reached["step"] = step + 1
            raise StopIteration

    loss = lambda traj, scene: jnp.sum(res(traj, scene) ** 2) / noise**2

    def run():
        try:
            _fit.fit(
                start, loss, ["Cd", "CdAx"], steps=adam_steps, learning_rate=0.05,
                print_every=None, callback=callback, **kw,
            )  # fmt: skip
        except StopIteration:
            pass

    _, adam_wall, _ = C.clock(run)
    n = reached.get("step")
    row = dict(
        c_n=ls.values["Cd"],
        c_n_std=ls.std["Cd"],
        c_t=ls.values["CdAx"],
        c_t_std=ls.std["CdAx"],
        c_n_true=truth["Cd"],
        c_t_true=truth["CdAx"],
        lm_iterations=ls.iterations,
        lm_solves=ls.solves,
        lm_wall_s=ls_wall,
        adam_steps=n if n is not None else f"> {adam_steps}",
        adam_solves=2 * n if n is not None else f"> {2 * adam_steps}",
        adam_wall_s=adam_wall,
        solves_ratio=2 * (n if n is not None else adam_steps) / ls.solves,
        converged=ls.converged,
    )
    C.write_table(
        "identify_tether_least_squares",
        [row],
        list(row),
        "Tether: (c_n, c_t) from the running-end force, Levenberg-Marquardt vs Adam",
        [
            f"Data: N = {2 * N_fit} chain at rtol 1e-10 with {noise} N noise; fit: "
            f"N = {N_fit}, Dopri5 at rtol 1e-8, start 30 % low on both coefficients. "
            "c_t is the drag's coefficient on the wetted surface (the scene's c_t/pi).",
            "Adam: learning rate 0.05 on log p, one forward and one reverse solve per "
            "step, until both coefficients lie within one reported standard "
            "deviation of the least-squares estimate; solves_ratio is a lower bound "
            "where Adam did not get there within its budget. Wall times include "
            "compilation. The fitted values carry the coarse chain's "
            "discretisation bias (see identify_tether.md).",
        ],
    )
    print(row)
    return row


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--least-squares", action="store_true")
    a = p.parse_args()
    if a.least_squares:
        C.set_quick(a.quick)
        least_squares_vs_adam()
    else:
        main(quick=a.quick)
