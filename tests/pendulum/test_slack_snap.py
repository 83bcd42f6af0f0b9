"""The string going slack and snapping taut: the smoothed tension-only law.

`Slack(smoothing=eps_s)` blends the onset of tension over the strains [0, eps_s]
(jaxstring/pendulum/effects.py); the sharp law is `smoothing=0`.
"""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _fit

from ..helpers import assert_grad_matches_central_differences


EPS_S = 1e-3
EA = 1e4


def _force(law, eps, eps_dot=0.0, alpha=0.0):
    """Axial force of `law` after Kelvin-Voigt with constant alpha, N."""
    N = EA * (eps + alpha * eps_dot)
    return law.tension(N, eps, eps_dot, EA)


def test_smoothed_law_is_the_sharp_one_outside_the_blend():
    smooth, sharp = js.Slack(smoothing=EPS_S), js.Slack(smoothing=0.0)
    rng = np.random.default_rng(0)
    eps = jnp.asarray(rng.uniform(-0.05, 0.05, 2000))
    eps_dot = jnp.asarray(rng.uniform(-5.0, 5.0, 2000))
    a, b = _force(smooth, eps, eps_dot, 0.01), _force(sharp, eps, eps_dot, 0.01)
    u = eps + 0.01 * eps_dot
    outside = np.asarray((eps >= EPS_S) & (u >= EPS_S))
    assert outside.sum() > 300
    np.testing.assert_array_equal(np.asarray(a)[outside], np.asarray(b)[outside])
    # Compressed or pushing: no force at all, under both laws.
    slack = np.asarray((eps <= 0) | (u <= 0))
    assert slack.sum() > 300
    assert np.all(np.asarray(a)[slack] == 0.0)
    # In between: never more than the sharp law, never negative.
    assert np.all(np.asarray(a) <= np.asarray(b) + 1e-9)
    assert np.all(np.asarray(a) >= 0.0)


def test_smoothed_law_deficit_bound_and_continuous_derivative():
    law = js.Slack(smoothing=EPS_S)
    eps = jnp.linspace(-2 * EPS_S, 3 * EPS_S, 50_001)
    N = _force(law, eps)
    # Elastic string: the force differs from EA max(eps, 0) by at most
    # max_z (z - g(z) r(z)) = 0.3166 EA eps_s (at z = 0.456).
    deficit = float(jnp.max(EA * jnp.maximum(eps, 0.0) - N)) / (EA * EPS_S)
    assert 0.316 < deficit < 0.317, deficit
    # C1: the derivative dN/d eps has no jump (the sharp law's jumps by EA).
    dN = jax.vmap(jax.grad(lambda e: _force(law, e)))(eps)
    assert float(jnp.max(jnp.abs(jnp.diff(dN)))) < 1e-3 * EA
    assert float(dN[0]) == 0.0 and abs(float(dN[-1]) - EA) < 1e-9 * EA
    # The stored energy EA/2 e(eps)^2 is the integral of the force.
    W = lambda e: 0.5 * EA * law.elastic_strain(e) ** 2
    dW = jax.vmap(jax.grad(W))(eps)
    assert float(jnp.max(jnp.abs(dW - N))) < 1e-9 * EA * EPS_S
    np.testing.assert_allclose(
        float(W(jnp.asarray(2 * EPS_S))), 0.5 * EA * (4 - 38 / 105) * EPS_S**2
    )


def test_smoothing_is_checked():
    with pytest.raises(ValueError, match="smoothing"):
        js.Slack(smoothing=-1e-7)
    with pytest.raises(ValueError, match="slack_smoothing"):
        js.string_pendulum(effects=("slack",), slack_smoothing=float("nan"))


# The paper's hard case: EA = 1e8 N released from 3 pi/4 (free fall, then a snap),
# alpha = 0.01, 2 s, k = 10; the smoothed law's default transition strain.
SNAP = dict(EA=1e8, theta0=3 * math.pi / 4, alpha=0.01, k=10, t1=2.0)
TS = jnp.linspace(0.0, 2.0, 41)


def _snap(formulation, smoothing):
    return js.string_pendulum(
        formulation=formulation,
        effects=("gravity", "kelvin_voigt", "slack"),
        slack_smoothing=smoothing,
        **SNAP,
    )


@pytest.mark.parametrize(
    "formulation", [pytest.param("natural", marks=pytest.mark.slow), "angle"]
)
def test_snap_completes_and_agrees_with_the_sharp_limit(formulation):
    scene = _snap(formulation, None)  # the scene's default smoothing
    assert scene.effects[2].smoothing == 1e-7
    traj = js.simulate(scene, "rodas5p", rtol=1e-6, atol=1e-6, ts=TS)
    assert traj.ok, traj.status
    # It went slack and snapped taut.
    assert float(jnp.min(traj.strain)) < -0.1
    assert float(jnp.max(traj.tension)) > 10 * 2 * 9.81  # 10x the weight
    # The sharp law's tight solve does not complete (Rodas5P at rtol 1e-8 stalls at
    # its kinks); its limit is taken as the law with a 100x narrower blend at
    # rtol 1e-9 (the change from eps_s = 1e-8 to 1e-9 is < 1e-5 m,
    # experiments/results/slack_snap_smoothing.md).
    ref = js.simulate(_snap(formulation, 1e-9), "rodas5p", rtol=1e-9, atol=1e-9, ts=TS)
    tight = js.simulate(scene, "rodas5p", rtol=1e-9, atol=1e-9, ts=TS)
    assert ref.ok and tight.ok
    dist = lambda a, b: float(jnp.max(jnp.linalg.norm(a.end_mass - b.end_mass, -1)))
    # The effect of the smoothing alone, both at rtol 1e-9 (measured 4.1e-5 m;
    # 1.2e-6 m for eps_s = 1e-8: 15-30x less per decade of eps_s) ...
    smoothing_effect = dist(tight, ref)
    assert smoothing_effect < 2e-4, smoothing_effect
    # ... is far below the error of the rtol = 1e-6 solve (measured 1.2e-3 and
    # 2.1e-3 m over 41 save times in two runs: the snaps amplify rounding
    # differences of the multithreaded vector field), which falls with the
    # tolerance.
    err = dist(traj, ref)
    assert 5 * smoothing_effect < err < 5e-3, err
    finer = js.simulate(scene, "rodas5p", rtol=1e-8, atol=1e-8, ts=TS)
    assert dist(finer, ref) < 0.2 * err, dist(finer, ref)


def _end_loss(traj, scene):
    del scene
    return jnp.sum(traj.obs["positions"][-1, -1, :] * jnp.array([1.0, 0.5]))


@pytest.mark.slow
def test_gradient_through_a_snap_matches_central_differences():
    # Released from 3 pi/4, the string falls slack, comes taut at t ~ 0.2 s and
    # snaps at 0.54 s (1 kN, 50x the weight): the end-mass position at 0.6 s,
    # differentiated with respect to alpha and EA through the smoothed law, against
    # central differences.
    scene = js.string_pendulum(
        formulation="angle",
        k=4,
        EA=1e6,
        alpha=0.01,
        theta0=3 * math.pi / 4,
        t1=0.6,
        effects=("gravity", "kelvin_voigt", "slack"),
    )
    kw = dict(solver="rodas5p", rtol=1e-11, atol=1e-11, n_save=61)
    config = _fit.SolveConfig(**kw)
    traj = _fit.solve(scene, config)
    assert traj.ok
    assert float(jnp.min(traj.strain)) < -0.01  # slack ...
    assert float(jnp.max(traj.tension)) > 500.0  # ... then snapped taut
    _, grad = _fit.value_and_grad(
        scene, _end_loss, ["alpha", "EA"], adjoint="forward", **kw
    )
    assert_grad_matches_central_differences(
        lambda s: _end_loss(_fit.solve(s, config), s), scene, grad
    )


def _snap_scene(t1):
    return js.string_pendulum(
        formulation="angle",
        k=4,
        EA=1e6,
        alpha=0.01,
        theta0=3 * math.pi / 4,
        t1=t1,
        effects=("gravity", "kelvin_voigt", "slack"),
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    "solver, rtol, t1",
    [("rodas5p", 1e-10, 2.0), ("kvaerno5", 1e-9, 0.6)],
)
def test_sensitivities_give_the_gradient_through_snaps(solver, rtol, t1):
    # Differentiated along the state's own steps (forward mode), the end-mass
    # position after several snaps (2 s) is off by 1e-3 relative even at rtol 1e-11.
    # With the sensitivities integrated beside the state, under its error control,
    # Rodas5P (2 s) and Kvaerno5 (0.6 s) match central differences of tight solves
    # (rtol 1e-11, steps of 1e-5 of the value; a step of 1e-4 in EA already
    # crosses a change of the snap sequence). Rodas5P's d/dEA over 2 s at rtol
    # 1e-9 was 1.4e-5 from them on one machine (8.64242e-8 against 8.64231e-8),
    # at 1e-10 2e-6 (8.64229e-8; central differences at 1e-12 and steps of 1e-5
    # and 3e-6 of EA: 8.64230e-8, 8.64232e-8).
    scene = _snap_scene(t1)
    n_save = int(round(t1 * 100)) + 1
    kw = dict(solver=solver, rtol=rtol, atol=rtol, n_save=n_save, max_steps=1_000_000)
    _, grad = _fit.value_and_grad(
        scene, _end_loss, ["alpha", "EA"], adjoint="sensitivity", **kw
    )
    config = _fit.SolveConfig(
        solver="rodas5p", rtol=1e-11, atol=1e-11, n_save=n_save, max_steps=1_000_000
    )
    assert_grad_matches_central_differences(
        lambda s: _end_loss(_fit.solve(s, config), s), scene, grad, rel_step=1e-5
    )


@pytest.mark.slow
def test_forward_mode_kvaerno5_differentiates_through_a_snap():
    # A stage iteration that fails (the step is then rejected) returns its starting
    # guess: its diverged last iterate made the linearisation of the stage
    # non-finite, and lineax's check ended the whole differentiated solve at the
    # first snap (rtol 1e-8, 11 save times). Through one snap forward mode is
    # accurate: central differences of rtol-1e-11 solves to 1e-4.
    scene = _snap_scene(0.6)
    loss = lambda traj, s: jnp.sum(traj.obs["positions"][-1, -1, :])
    kw = dict(solver="kvaerno5", rtol=1e-8, atol=1e-8, n_save=11)
    _, grad = _fit.value_and_grad(scene, loss, ["alpha", "EA"], adjoint="forward", **kw)
    config = _fit.SolveConfig(solver="rodas5p", rtol=1e-11, atol=1e-11, n_save=11)
    assert_grad_matches_central_differences(
        lambda s: loss(_fit.solve(s, config), s), scene, grad, rel_step=1e-5, rtol=1e-4
    )
