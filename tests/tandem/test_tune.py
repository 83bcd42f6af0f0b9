"""Tuning the tanker compensator's gains by gradient descent through diffrax
(experiments/tune_tanker.py): the reverse-mode gradient of the tanker cost with
respect to the gains against central finite differences, and a few optimiser steps
lowering the cost on a short window and on a longer run it was not trained on."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax
import pytest
import tune_tanker as tt

import jaxstring as js
from jaxstring import _fit
from jaxstring.tandem.scenes import tandem_controlled


GAINS = ("K_P", "K_D")


def _get(name):
    return lambda s: getattr(s.effects[-1], name)


@pytest.mark.slow
def test_gain_gradient_matches_central_differences():
    # Wind at 90 deg: both channels and the actuator (saturating yaw moment) active.
    scene = tandem_controlled(env="wind15_90", t1=200.0)
    # rtol 1e-12: the gradient differentiates the solver's stages, not its step-size
    # choices; at rtol 1e-10 that leaves a 1e-3 relative gap on the weakest component
    # (d/dK_P of the span channel), at 1e-12 about 1e-7.
    kw = dict(solver="tsit5", rtol=1e-12, atol=1e-12, n_save=101, max_steps=50_000)
    _, grad = _fit.value_and_grad(
        scene, tt.scene_cost, list(GAINS), checkpoints=5_000, **kw
    )
    config = _fit.SolveConfig(**kw)
    loss = eqx.filter_jit(lambda s: tt.scene_cost(_fit.solve(s, config), s))
    for name in GAINS:
        p = np.asarray(getattr(scene.effects[-1], name))
        for i in range(2):
            h = 1e-3 * p[i]
            vals = []
            for sign in (1, -1):
                q = p.copy()
                q[i] += sign * h
                sc = eqx.tree_at(_get(name), scene, jnp.asarray(q))
                vals.append(float(loss(sc)))
            fd = (vals[0] - vals[1]) / (2 * h)
            g = float(grad[name][i])
            # Truncation ~ (h/p)^2 = 1e-6; solver noise ~ 1e-12 / 1e-3.
            assert abs(g - fd) <= 1e-4 * abs(fd), f"d/d{name}[{i}]: {g} vs fd {fd}"


@pytest.mark.slow
def test_tuned_gains_lower_the_cost():
    # A few Adam steps on the log gains over a 200 s window from the S4 start.
    scene = tandem_controlled(env="wind15_180", t1=200.0)
    res = _fit.fit(
        scene,
        tt.scene_cost,
        list(GAINS),
        steps=5,
        optimizer=optax.adam(0.1),
        solver="tsit5",
        rtol=1e-8,
        atol=1e-8,
        n_save=101,
        max_steps=20_000,
        print_every=None,
    )
    i = int(np.nanargmin(res.losses))
    assert i > 0 and res.losses[i] < 0.97 * res.losses[0]
    K_P, K_D = res.params["K_P"][i], res.params["K_D"][i]
    # On a 5x longer run than the training window, and in another environment, the
    # tuned gains still cost less, keep the hulls apart and the actuator in limits.
    for env in ("wind15_180", "wind5_0"):
        costs = []
        for kp, kd in ((res.params["K_P"][0], res.params["K_D"][0]), (K_P, K_D)):
            sc = tt.with_gains(
                tandem_controlled(env=env, t1=1000.0), jnp.asarray(kp), jnp.asarray(kd)
            )
            traj = js.simulate(
                sc, "tsit5", rtol=1e-8, atol=1e-8, ts=jnp.linspace(0, 1000.0, 501)
            )
            assert traj.ok
            ctl = sc.effects[-1]
            assert float(np.min(traj.clearance)) > 0
            assert float(np.max(np.abs(traj.control[:, 0]))) <= float(ctl.X_max)
            assert float(np.max(np.abs(traj.control[:, 1]))) <= float(ctl.N_max)
            costs.append(float(tt.scene_cost(traj, sc)))
        assert costs[1] < costs[0], (env, costs)
