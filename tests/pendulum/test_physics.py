"""Physics of the string pendulum: analytic limits, conservation, convergence."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import jaxstring as js

from ..helpers import FORMULATIONS, FORMULATIONS_FAST, fitted_order, run, zero_crossings


G = 9.81


def _axial_mode_scene(formulation, k, EA, V, t1):
    """Vertical string, unstrained, with the first axial mode's velocity field."""
    mu = m_s = l = 1.0
    beta = scipy.optimize.brentq(lambda b: b * math.tan(b) - mu * l / m_s, 1e-6, 1.5)
    base = js.string_pendulum(
        formulation=formulation, k=k, EA=EA, alpha=0.0, theta0=0.0, t1=t1, effects=()
    )
    y0 = np.array(base.y0)
    s = np.arange(k + 1) * l / k
    if formulation == "displacement":
        y0[:, 3] = -V * np.sin(beta * s[1:] / l)  # downward velocity of nodes 1..k
    else:  # strain rate = d(axial velocity)/ds; column of eps' in the state
        col = 2 if formulation == "angle" else 3
        y0[:, col] = V * (beta / l) * np.cos(beta * s / l)
    scene = js.string_pendulum(
        formulation=formulation,
        k=k,
        EA=EA,
        alpha=0.0,
        theta0=0.0,
        t1=t1,
        effects=(),
        y0=jnp.asarray(y0),
    )
    omega = beta / l * math.sqrt(EA / mu)
    return scene, omega


# The natural form integrates the displacement form's mechanics (the formulations'
# agreement: test_natural_and_angle_forms_are_one_semi_discrete_system and the slow
# convergence test): its analytic limits are slow checks.
DISPLACEMENT_FAST = (
    "displacement",
    *(pytest.param(f, marks=pytest.mark.slow) for f in FORMULATIONS[1:]),
)


@pytest.mark.parametrize("formulation", DISPLACEMENT_FAST)
def test_axial_frequency_of_bar_with_tip_mass(formulation):
    # beta tan(beta) = mu l / m_s, omega = (beta / l) sqrt(EA / mu): within 1 % at k=40.
    scene, omega = _axial_mode_scene(formulation, k=40, EA=1e4, V=1e-3, t1=0.25)
    ts = jnp.linspace(0.0, 0.25, 2501)
    traj = js.simulate(scene, "kvaerno5", rtol=1e-10, atol=1e-12, ts=ts)
    assert traj.ok, traj.status
    u = np.asarray(traj.end_mass[:, 1]) + 1.0  # axial displacement of the end mass
    crossings = zero_crossings(ts, u)[1:]  # drop t = 0
    assert len(crossings) >= 5
    period = 2 * np.mean(np.diff(crossings))
    rel = abs(2 * math.pi / period - omega) / omega
    assert rel < 0.01, f"{formulation}: omega error {rel:.2e}"


@pytest.mark.parametrize("formulation", DISPLACEMENT_FAST)
def test_small_amplitude_period_light_string(formulation):
    # mu l = 1e-3 m_s: a simple pendulum of the stretched length, with the compound
    # correction of the string mass and the finite-amplitude factor (1 + theta0^2/16).
    mu, m_s, l, EA, theta0 = 1e-3, 1.0, 1.0, 1e6, 0.05
    traj = run(formulation, EA=EA, mu=mu, m_s=m_s, theta0=theta0, t1=3.9)
    assert traj.ok, traj.status
    L = l * (1 + m_s * G / EA)
    T0 = (
        2
        * math.pi
        * math.sqrt((m_s * L**2 + mu * L**3 / 3) / (G * (m_s * L + mu * L**2 / 2)))
    )
    T_exact = T0 * (1 + theta0**2 / 16)
    crossings = zero_crossings(traj.ts, traj.end_mass[:, 0])
    assert len(crossings) >= 3
    period = 2 * np.mean(np.diff(crossings))
    rel = abs(period - T_exact) / T_exact
    assert rel < 0.005, f"{formulation}: period {period:.5f} vs {T_exact:.5f}"


@pytest.mark.parametrize("formulation", FORMULATIONS_FAST)
def test_energy_conserved_without_dissipation(formulation):
    traj = run(formulation, alpha=0.0, t1=2.0, rtol=1e-9, atol=1e-9)
    assert traj.ok, traj.status
    e = np.asarray(traj.energy)
    scale = (1.0 + 1.0) * G * 1.0  # (mu l + m_s) g l
    drift = np.max(np.abs(e - e[0])) / scale
    assert drift < 1e-6, f"{formulation}: relative energy drift {drift:.2e}"


@pytest.mark.parametrize("formulation", FORMULATIONS_FAST)
def test_energy_never_increases_with_dissipation(formulation):
    traj = run(formulation, alpha=0.01, t1=2.0, rtol=1e-9, atol=1e-9)
    assert traj.ok, traj.status
    e = np.asarray(traj.energy)
    scale = 2.0 * G
    assert np.max(np.diff(e)) <= 1e-8 * scale, np.max(np.diff(e))
    assert e[-1] < e[0] - 0.01 * scale  # and it does dissipate


def test_natural_and_angle_forms_are_one_semi_discrete_system():
    # The two natural-variable forms integrate the same ODE (the fast check; the
    # convergence of the displacement form towards them is the slow test below).
    n = run("natural", k=10, n_save=101)
    a = run("angle", k=10, n_save=101)
    assert n.ok and a.ok
    gap = float(np.max(np.abs(n.end_mass - a.end_mass)))
    assert gap < 1e-6, gap
    assert float(np.max(np.abs(a.end_mass[:, 0]))) > 0.5  # it really swings


@pytest.mark.slow
def test_formulations_agree_and_converge_with_k():
    ks = (10, 20, 40)
    diffs = []
    for k in ks:
        # Rodas5P at 1e-8: solver error far below the O(1/k) gaps measured here.
        d = run("displacement", k=k, n_save=101, solver="rodas5p")
        a = run("angle", k=k, n_save=101, solver="rodas5p")
        assert d.ok and a.ok
        diffs.append(float(np.max(np.linalg.norm(d.end_mass - a.end_mass, axis=1))))
    order = fitted_order([1 / k for k in ks], diffs)
    # Both discretisations are first order at the end mass (the paper's lumping).
    assert diffs[0] > diffs[1] > diffs[2], diffs
    assert 0.8 < order < 1.3, (order, diffs)
    assert diffs[-1] < 5e-3, diffs
    # The two natural-variable forms are the same semi-discrete system.
    for k in (10, 20):
        n = run("natural", k=k, n_save=101, solver="rodas5p")
        a = run("angle", k=k, n_save=101, solver="rodas5p")
        gap = float(np.max(np.abs(n.end_mass - a.end_mass)))
        assert gap < 1e-6, (k, gap)


HARD_CASES = {
    "EA=1e9": dict(EA=1e9),
    "alpha=0,EA=1e6": dict(EA=1e6, alpha=0.0),
    "slack-snap": dict(
        EA=1e6, theta0=3 * math.pi / 4, effects=("gravity", "kelvin_voigt", "slack")
    ),
}


# The default run's hard cases: tests/pendulum/test_hard_cases.py, test_slack_snap.py.
@pytest.mark.slow
@pytest.mark.parametrize("case", list(HARD_CASES))
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_hard_cases_integrate(formulation, case):
    kw = HARD_CASES[case]
    max_steps = 200_000
    traj = run(
        formulation,
        k=10,
        t1=1.0,
        rtol=1e-6,
        atol=1e-6,
        n_save=101,
        max_steps=max_steps,
        **kw,
    )
    assert traj.ok, traj.status
    assert np.all(np.isfinite(np.asarray(traj.ys)))
    assert int(traj.stats["num_steps"]) < max_steps
    assert float(np.max(traj.constraint_error)) < 1e-8
    if case == "slack-snap":
        # The string went slack (compressed geometry, zero tension) and snapped taut.
        assert float(np.min(traj.strain)) < -0.1
        assert float(np.min(traj.tension[:, 0])) == 0.0
        assert float(np.max(traj.tension)) > 10 * 2 * G


def test_tangent_projection_prevents_drift():
    scene = js.string_pendulum(formulation="natural", k=10, EA=1e6, t1=1.0)
    ts = jnp.linspace(0.0, 1.0, 101)
    raw = js.simulate(scene, rtol=1e-6, atol=1e-6, ts=ts, project=False)
    kept = js.simulate(scene, rtol=1e-6, atol=1e-6, ts=ts)
    assert raw.ok and kept.ok
    assert float(np.max(raw.constraint_error)) > 1e-8  # drifts without projection
    assert float(np.max(kept.constraint_error)) < 1e-12


@pytest.mark.slow
def test_three_d_planar_motion_matches_two_d():
    for formulation in ("displacement", "natural"):
        two = run(formulation, k=10, t1=0.5, n_save=51)
        three = run(formulation, k=10, t1=0.5, n_save=51, dim=3)
        assert two.ok and three.ok
        np.testing.assert_allclose(three.positions[..., :2], two.positions, atol=1e-7)
        assert float(np.max(np.abs(three.positions[..., 2]))) == 0.0


def _conical_swing(formulation):
    """End-mass path of a conical swing (out-of-plane velocity at release) over
    1 s, k = 10, no dissipation; its energy is conserved to 1e-6 of m g L and it
    really leaves the plane."""
    args = dict(formulation=formulation, k=10, EA=1e4, alpha=0.0, dim=3, t1=1.0)
    y0 = np.array(js.string_pendulum(**args).y0)
    s = np.arange(11) / 10
    if formulation == "displacement":
        y0[:, 5] = 2.0 * s[1:]  # z-velocity of nodes, rigid rotation about y
    else:
        y0[:, 7] = 2.0  # dt/dt = omega x t: z-component of t'
    scene = js.string_pendulum(**args, y0=jnp.asarray(y0))
    traj = js.simulate(scene, rtol=1e-9, atol=1e-9, ts=jnp.linspace(0, 1, 51))
    assert traj.ok, traj.status
    e = np.asarray(traj.energy)
    assert np.max(np.abs(e - e[0])) / (2 * G) < 1e-6
    assert float(np.max(np.abs(traj.end_mass[:, 2]))) > 0.1  # really 3D
    return np.asarray(traj.end_mass)


def test_three_d_out_of_plane_swing_conserves_energy():
    _conical_swing("displacement")


# Slow: the natural variables' 3-D program is the costliest compilation of the
# pendulum tests; the default run checks the 3-D mechanics in displacement
# variables (above) and the natural variables' conservation in 2-D.
@pytest.mark.slow
def test_three_d_out_of_plane_swing_agrees_between_formulations():
    gap = np.max(
        np.linalg.norm(
            _conical_swing("displacement") - _conical_swing("natural"), axis=1
        )
    )
    assert gap < 0.03, gap  # same O(1/k) discretisation gap as in 2D at k = 10
