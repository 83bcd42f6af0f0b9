"""The strongest peers (jaxstring/testing/peers.py) solve jaxstring's equations.

peers.py is an independent NumPy/numba implementation of the string pendulum in the
three formulations and of the lumped-mass tether; here each right-hand side and the
analytic banded Jacobian of displacement variables are checked against jaxstring's
vector field (and jax.jacfwd of it) to 1e-12 relative, at states with slack and
compressed elements where the tension-only law is on, and CVODE and scipy's Radau
on the compiled functions agree on the motion. Skipped without the bench extra.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js


pytest.importorskip("numba")
pytest.importorskip("sksundae")
from jaxstring.testing import peers


K = 6
EA = 1e6
ALPHA = 0.02


def _scene(form, slack):
    effects = ("gravity", "kelvin_voigt") + (("slack",) if slack else ())
    return js.string_pendulum(
        formulation=form, k=K, EA=EA, alpha=ALPHA, m_s=0.7, mu=1.3, l=1.1,
        theta0=1.1, effects=effects,
    )  # fmt: skip


def _state(scene, form, slack):
    """A state near the release with strains of both signs and, under the slack
    law, elements whose damping would push (eps > 0, N < 0)."""
    rng = np.random.default_rng(1)
    y = np.asarray(scene.y0, dtype=np.float64).copy()
    y = y + 1e-3 * rng.standard_normal(y.shape)
    if form == "displacement":
        # Nodes 1, 3, 5 pulled in: elements 0, 2, 4 slack, 1, 3, 5 stretched;
        # speeds along the string make element 1 shorten fast (N < 0), 3 lengthen.
        y[::2, :2] *= 1 - 2e-3
        along = np.array([0.0, -1.0, -1.0, 1.0, 1.0, 1.0])[:, None]
        tangent = y[-1, :2] / np.linalg.norm(y[-1, :2])
        y[:, 2:] = along * tangent + 0.1 * rng.standard_normal((K, 2))
    else:
        eps = 1e-3 * np.where(np.arange(K + 1) % 3 == 0, -1.0, 1.0)
        y[:, 0] = eps
        rate = y.shape[1] // 2
        y[:, rate] = np.where(np.arange(K + 1) % 3 == 1, -0.2, 0.02)
        y[:, rate + 1 :] += rng.standard_normal(y[:, rate + 1 :].shape)
    return y


def _strains(scene, y):
    eps, eps_dot = scene.model.strain(jnp.asarray(y))
    return np.asarray(eps), np.asarray(eps_dot)


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("slack", [False, True])
@pytest.mark.parametrize("form", peers.FORMULATIONS)
def test_pendulum_rhs_matches_jaxstring(form, slack):
    scene = _scene(form, slack)
    peer = peers.make_rhs(form, K, EA, alpha=ALPHA, l=1.1, mu=1.3, m_s=0.7, slack=slack)
    np.testing.assert_allclose(
        peer.initial_state(1.1), np.ravel(scene.y0), rtol=0, atol=1e-15
    )
    y = _state(scene, form, slack)
    eps, eps_dot = _strains(scene, y)
    if slack:  # the state exercises every branch of the tension-only law
        N = EA * (eps + ALPHA * eps_dot)
        assert np.any(eps <= 0) and np.any((eps > 0) & (N < 0))
        assert np.any((eps > 0) & (N > 0))
    f_js = np.ravel(scene.vector_field(0.3, jnp.asarray(y)))
    f_peer = peer.f(0.3, np.ravel(y))
    assert _rel(f_peer, f_js) < 1e-12
    end = np.asarray(scene.observables(jnp.asarray(y))["positions"][-1])
    np.testing.assert_allclose(peer.end_mass(np.ravel(y))[0], end, atol=1e-14)


@pytest.mark.parametrize("slack", [False, True])
def test_displacement_jacobian_matches_jacfwd(slack):
    scene = _scene("displacement", slack)
    peer = peers.make_rhs(
        "displacement", K, EA, alpha=ALPHA, l=1.1, mu=1.3, m_s=0.7, slack=slack
    )
    y = _state(scene, "displacement", slack)
    shape = y.shape
    J_js = np.asarray(
        jax.jacfwd(lambda z: jnp.ravel(scene.vector_field(0.0, z.reshape(shape))))(
            jnp.ravel(jnp.asarray(y))
        )
    )
    JJ = np.full((peer.n, peer.n), np.nan)  # entries outside the band stay unset
    peer.jac(0.0, np.ravel(y), JJ)
    i, j = np.indices(JJ.shape)
    band = np.abs(i - j) <= peer.lband
    assert not np.any(J_js[~band])  # the whole Jacobian lies inside the band
    assert _rel(JJ[band], J_js[band]) < 1e-12


def test_tether_rhs_matches_jaxstring_lms():
    scene = js.tether_fixed(method="lms", N=9, c_lms=3.0, c_l=0.3)
    peer = peers.make_tether(N=9, c_s=3.0, c_l=0.3)
    rng = np.random.default_rng(2)
    y0 = np.asarray(scene.y0, dtype=np.float64)
    for t in (0.0, 12.0, 50.0, 80.0):  # still, rising, moving forward, after the path
        y = y0 + np.concatenate(
            [1e-2 * rng.standard_normal((9, 3)), rng.standard_normal((9, 3))], axis=1
        )
        f_js = np.ravel(scene.vector_field(t, jnp.asarray(y)))
        assert _rel(peer.f(t, np.ravel(y)), f_js) < 1e-12


def test_cvode_and_radau_agree_on_the_swing():
    """Two integrators of different families on the compiled functions: CVODE (BDF,
    analytic band Jacobian and difference quotients) and scipy's Radau meet to
    well below their tolerances' error, and the end mass falls by the pendulum's
    kinematics (its height drops while it swings towards the bottom)."""
    peer = peers.make_rhs("displacement", K, EA)
    ts = np.linspace(0.0, 0.3, 4)
    y0 = peer.initial_state()
    a = peers.cvode_solve(peer, ts, y0, 1e-10, 1e-10, jac="analytic")
    b = peers.cvode_solve(peer, ts, y0, 1e-10, 1e-10, jac="dq")
    c = peers.scipy_solve(peer, "Radau", ts, y0, 1e-10, 1e-10, jac="dq")
    assert a["ok"] and b["ok"] and c["ok"]
    ea, eb, ec = (peer.end_mass(o["ys"]) for o in (a, b, c))
    assert np.max(np.abs(ea - eb)) < 1e-7
    assert np.max(np.abs(ea - ec)) < 1e-7
    # Free fall bound: the end mass cannot drop faster than g t^2 / 2.
    drop = ea[0, 1] - ea[:, 1]
    assert np.all(np.diff(drop) > 0)
    assert np.all(drop <= 0.5 * 9.81 * ts**2 + 1e-9)
