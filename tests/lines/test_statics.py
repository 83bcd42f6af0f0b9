"""Static equilibrium and stiffness of catenary mooring systems
(`jaxstring.lines.statics`), checked with numbers:

- OC3-Hywind (lines.txt), fairleads held: tensions as MoorPy's System gives them
  (737.2 / 911.4 kN on line 1) within 1e-6, the 9x9 coupled stiffness of the
  three fairleads as MoorPy's analytic `getCoupledStiffnessA` within 1e-5 and its
  finite-difference `getCoupledStiffness` within 1 %;
- the same with the fairleads on one coupled body: the 6x6 stiffness against
  MoorPy, and the structure physics gives it (translational block symmetric,
  cross blocks transposes, K_rr - K_rr^T = skew(M) with M the lines' moment);
- a coupled body's load equals the sum of its fairlead forces and their moment.

Free bodies and points, and bad input: test_statics_free.py; derivatives:
test_statics_grad.py.

MoorPy is the independent reference (`pytest.importorskip`).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines import (
    Body,
    coupled_stiffness,
    mooring_system,
    skew,
)


DECK = lines.case_path("lines.txt")


def _moorpy():
    pytest.importorskip("moorpy")  # the peer module imports it when called
    from jaxstring.testing import moorpy_peer

    return moorpy_peer


@pytest.fixture(scope="module")
def points_case():
    s = mooring_system(DECK, g=9.81)
    K, out = coupled_stiffness(s)
    return s, np.asarray(K), out


@pytest.fixture(scope="module")
def body_case():
    s = mooring_system(DECK, g=9.81, vessel=Body("coupled", position=[0.0, 0.0, 0.0]))
    K, out = coupled_stiffness(s)
    return s, np.asarray(K), out


def test_oc3_fairleads_held(points_case):
    s, K, out = points_case
    assert bool(out.converged) and int(out.status) == 0 and out.message == "converged"
    T = np.asarray(out.tension)
    np.testing.assert_allclose(T[0] / 1e3, [737.2, 911.4], atol=0.05)
    assert s.n_free == 0 and s.n_coupled == 9
    # the coupled force on each fairlead is its line's pull
    np.testing.assert_allclose(
        np.asarray(out.coupled_force).reshape(3, 3), np.asarray(out.line_force[:, 1])
    )
    mp = _moorpy()
    ms = mp.moorpy_system(s)
    ms.solveEquilibrium()
    np.testing.assert_allclose(T, mp.moorpy_tensions(ms), rtol=1e-6)
    KA = ms.getCoupledStiffnessA()
    np.testing.assert_allclose(K, KA, rtol=0, atol=1e-5 * np.abs(KA).max())
    # MoorPy's finite differences: within 1 % on every entry above 1e-3 of the
    # largest (the others are zero by symmetry)
    KF = ms.getCoupledStiffness()
    big = np.abs(KF) > 1e-3 * np.abs(KF).max()
    np.testing.assert_allclose(K[big], KF[big], rtol=1e-2)
    assert np.all(np.abs(K[~big]) < 1e-3 * np.abs(KF).max())
    # a held point's stiffness is its line's: symmetric
    np.testing.assert_allclose(K, K.T, atol=1e-9 * np.abs(K).max())


def test_coupled_body_stiffness(body_case):
    s, K, out = body_case
    assert bool(out.converged)
    F = np.asarray(out.coupled_force)
    # the body's load is the sum of its fairlead forces, and their moment
    lf = np.asarray(out.line_force[:, 1])
    P = np.asarray(out.point_position)[[3, 4, 5]]
    np.testing.assert_allclose(F[:3], lf.sum(0), rtol=1e-12)
    np.testing.assert_allclose(F[3:], np.cross(P, lf).sum(0), atol=1e-6)
    # structure: translational block symmetric; cross blocks transposes; the
    # rotational block's asymmetry is the moment of the loads at the body
    scale = np.abs(K).max()
    np.testing.assert_allclose(K[:3, :3], K[:3, :3].T, atol=1e-10 * scale)
    np.testing.assert_allclose(K[:3, 3:], K[3:, :3].T, atol=1e-10 * scale)
    np.testing.assert_allclose(
        K[3:, 3:] - K[3:, 3:].T, np.asarray(skew(F[3:])), atol=1e-9 * scale
    )
    # three lines at 120 degrees: surge and sway stiffness equal (the deck's
    # anchors are rounded to 1 cm)
    np.testing.assert_allclose(K[0, 0], K[1, 1], rtol=1e-4)
    mp = _moorpy()
    ms = mp.moorpy_system(s)
    ms.solveEquilibrium()
    np.testing.assert_allclose(
        np.asarray(out.tension), mp.moorpy_tensions(ms), rtol=1e-6
    )
    KA = ms.getCoupledStiffnessA()
    np.testing.assert_allclose(K, KA, rtol=0, atol=1e-6 * scale)
    # MoorPy's finite differences with 0.01 rad rotations (its default 0.1 rad
    # moves the fairleads 7 m, 70 m below the reference point: its rotational
    # entries are then 2 % off its own analytic ones): within 1 % on the entries
    # that matter (1e-4 of the largest of their row or column)
    KF = ms.getCoupledStiffness(dth=0.01)
    big = np.abs(KF) > 1e-4 * np.minimum(
        np.abs(KF).max(1, keepdims=True), np.abs(KF).max(0, keepdims=True)
    )
    big &= np.abs(K) > 1e-4 * scale
    np.testing.assert_allclose(K[big], KF[big], rtol=1e-2)


def test_loads_dict_and_array_agree(points_case):
    s, _, _ = points_case
    a = s.loads(point={3: [1.0, 2.0, 3.0]})
    b = s.loads(point=jnp.zeros((6, 3)).at[3].set(jnp.array([1.0, 2.0, 3.0])))
    np.testing.assert_array_equal(np.asarray(a.point), np.asarray(b.point))
    assert a.body.shape == (0, 6)


def test_pinned_body_is_the_coupled_one_reduced(body_case):
    # a pinned body (position held, rotation free) settles where the lines'
    # moment vanishes; its 3x3 stiffness is the coupled body's 6x6 at that
    # rotation with the rotations condensed out
    s = mooring_system(DECK, g=9.81, vessel=Body("pinned", position=[0.0, 0.0, 0.0]))
    K3, out = coupled_stiffness(s)
    assert s.n_free == 3 and s.n_coupled == 3 and bool(out.converged)
    rot = np.asarray(out.body_rotation[0])
    assert 0 < np.abs(rot).max() < 1e-3  # the deck's rounding tilts it slightly
    held = eqx.tree_at(lambda s: s.bodies[0].rotation, body_case[0], jnp.asarray(rot))
    K6, out6 = coupled_stiffness(held)
    np.testing.assert_allclose(np.asarray(out6.coupled_force[3:]), 0.0, atol=1e-6)
    K6 = np.asarray(K6)
    schur = K6[:3, :3] - K6[:3, 3:] @ np.linalg.solve(K6[3:, 3:], K6[3:, :3])
    np.testing.assert_allclose(
        np.asarray(K3), schur, rtol=0, atol=1e-9 * np.abs(K6).max()
    )
