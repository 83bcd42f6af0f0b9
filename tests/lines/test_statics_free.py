"""Free bodies and points in the catenary statics, and bad input, checked with
numbers:

- a free spar (OC3-Hywind on lines.txt) under a surge force and a pitch moment:
  pose and tensions as MoorPy's `solveEquilibrium` within 1e-8;
- a buoy on a vertical tether: the analytic height (elastic stretch under the
  net buoyancy less the line's weight) to 1e-9 m, the tensions to 1e-12;
- bad input: a ValueError naming the argument and the range before anything
  compiles (an anchor below the seabed, a current, NaN loads, wrong shapes);
  loads no pose can hold (a spar heavier than its buoyancy on lines from below;
  a 100 MN pull on lines of EA = 1e15 N) end with a status that says so, and
  raise with `throw=True`; a line that would sag onto the seabed between two
  ends above it is reported, never returned as an equilibrium.

MoorPy is the independent reference (`pytest.importorskip`).
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines import (
    Body,
    MooringPoint,
    MooringSystem,
    mooring_equilibrium,
    mooring_system,
)


DECK = lines.case_path("lines.txt")
# OC3-Hywind spar with its turbine, reference point at the still-water line
SPAR = dict(mass=8.066e6, cg=[0.0, 0.0, -78.0], volume=8029.21)
K33 = 332941.0  # N/m, OC3's heave waterplane stiffness


def _moorpy():
    pytest.importorskip("moorpy")  # the peer module imports it when called
    from jaxstring.testing import moorpy_peer

    return moorpy_peer


@pytest.fixture(scope="module")
def spar_system():
    spar = Body("free", position=[0.0, 0.0, 0.0], name="spar", **SPAR)
    return mooring_system(
        DECK,
        g=9.81,
        vessel=spar,
        hydrostatics=np.diag([0.0, 0.0, K33, 0.0, 0.0, 0.0]),
        hydrostatic_pose=np.zeros(6),
    )


def test_free_spar_against_moorpy(spar_system):
    s = spar_system
    loads = s.loads(body={0: [1e6, 0.0, 0.0, 0.0, 2e7, 0.0]})
    out = mooring_equilibrium(s, loads)
    assert bool(out.converged) and 0 < int(out.iterations) < 30
    assert float(out.residual) <= 1e-10 * float(out.force_scale)
    mp = _moorpy()
    ms = mp.moorpy_system(s, loads)
    ms.solveEquilibrium(tol=1e-9, maxIter=500)
    r6 = ms.bodyList[0].r6
    # surge and pitch only (the load and the deck are symmetric in y)
    np.testing.assert_allclose(np.asarray(out.body_position[0]), r6[:3], atol=1e-7)
    np.testing.assert_allclose(np.asarray(out.body_rotation[0]), r6[3:], atol=1e-9)
    np.testing.assert_allclose(
        np.asarray(out.tension), mp.moorpy_tensions(ms), rtol=1e-8
    )
    assert float(out.body_position[0, 0]) > 1.0  # it moved downstream


def test_buoy_on_a_vertical_tether():
    # a buoy (net buoyancy B) on a 100 m tether from the seabed (50 m of water
    # above it): the top lies at L + (B L - W L^2/2)/EA above the anchor, and the
    # tension there is B
    L, EA, w, d, depth = 100.0, 2e6, 20.0, 0.05, 150.0
    rho, g = 1025.0, 9.80665
    vol, mass = 4.0, 500.0
    B = (rho * vol - mass) * g
    pts = (
        MooringPoint("fixed", [0.0, 0.0, -depth], name="anchor"),
        MooringPoint("free", [0.0, 0.0, -depth + L], mass, vol, name="buoy"),
    )
    s = MooringSystem((), pts, [(0, 1)], L, d, w, EA, depth=depth, g=g, rho=rho)
    out = mooring_equilibrium(s)
    W = (w - rho * math.pi / 4 * d * d) * g
    z = -depth + L + (B * L - 0.5 * W * L * L) / EA
    np.testing.assert_allclose(np.asarray(out.point_position[1]), [0, 0, z], atol=1e-9)
    np.testing.assert_allclose(np.asarray(out.tension[0]), [B - W * L, B], rtol=1e-12)
    assert s.n_free == 3


# ---------------------------------------------------------------------------
# Bad input


def test_anchor_below_the_seabed():
    pts = (
        MooringPoint("fixed", [0.0, 0.0, -151.0], name="anchor 1"),
        MooringPoint("coupled", [300.0, 0.0, -10.0], name="fairlead"),
    )
    with pytest.raises(ValueError, match=r"anchor 1 \(fixed\) lies below the seabed"):
        MooringSystem((), pts, [(0, 1)], 400.0, 0.1, 50.0, 1e9, depth=150.0)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(current=[0.5, 0.0, 0.0]), r"`current` = .*not modelled by the analytic"),
        (dict(loads=np.full((1, 6), np.nan)), r"`loads.body` must be finite"),
        (dict(loads=np.zeros((2, 6))), r"`loads.body` must be of shape \(1, 6\)"),
        (dict(guess=np.zeros(3)), r"`guess` must be of shape \(6,\)"),
        (dict(offsets=np.zeros(1)), r"`offsets` must be of shape \(0,\)"),
        (dict(tol=0.0), r"`tol` must be a finite number > 0"),
        (dict(max_iter=0), r"`max_iter` must be an integer >= 1"),
    ],
)
def test_bad_arguments(spar_system, kwargs, match):
    with pytest.raises(ValueError, match=match):
        mooring_equilibrium(spar_system, **kwargs)


def test_bad_system():
    pts = (
        MooringPoint("fixed", [0.0, 0.0, -150.0]),
        MooringPoint("coupled", [300.0, 0.0, -10.0]),
    )
    args = dict(bodies=(), points=pts, attach=[(0, 1)], L=400.0, d=0.1, w=50.0,
                EA=1e9, depth=150.0)  # fmt: skip
    for change, match in (
        (dict(L=-1.0), r"`L` must be a finite number > 0 m; got \[-1.\]"),
        (dict(EA=np.nan), r"`EA` must be finite"),
        (dict(attach=[(0, 2)]), r"`attach\[0\]` = \(0, 2\) must hold indices"),
        (dict(attach=[(1, 1)]), r"`attach\[0\]` joins point 1 to itself"),
        (dict(depth=-5.0), r"`depth` must be a finite number > 0 m; got -5.0"),
        (dict(L=[1.0, 2.0]), r"`L` must be of shape \(1,\)"),
    ):
        with pytest.raises(ValueError, match=match):
            MooringSystem(**{**args, **change})
    with pytest.raises(ValueError, match=r"unknown point kind 'anchor'"):
        MooringPoint("anchor", [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match=r"`body` of p must be the index"):
        MooringPoint("body", [0.0, 0.0, 0.0], name="p")


def test_no_equilibrium_is_reported(spar_system):
    # a spar heavier than its buoyancy, no waterplane: it sinks onto lines that
    # come from below and cannot hold it up
    s = eqx.tree_at(lambda s: s.hydrostatics, spar_system, jnp.zeros((1, 6, 6)))
    s = eqx.tree_at(lambda s: s.bodies[0].mass, s, jnp.asarray(9.5e6, jnp.float64))
    out = mooring_equilibrium(s, throw=False)
    assert not bool(out.converged) and int(out.status) == 2
    assert "no equilibrium near this start" in out.message
    assert float(out.residual) > 1e-3 * float(out.force_scale)
    with pytest.raises(Exception, match="no step that lowers the residual"):
        mooring_equilibrium(s)


def test_stiff_lines_pulled_hard(spar_system):
    # lines of EA = 1e15 N under a 100 MN pull: the pose the Newton iteration
    # cannot reach is not returned as an equilibrium
    s = eqx.tree_at(lambda s: s.EA, spar_system, jnp.full(3, 1e15))
    out = mooring_equilibrium(s, s.loads(body={0: [1e8, 0, 0, 0, 0, 0]}), throw=False)
    if bool(out.converged):  # then the pose is right: the lines hold the pull
        F = np.asarray(out.line_force[:, 1]).sum(0)
        np.testing.assert_allclose(F[0], -1e8, rtol=1e-9)
    else:
        assert int(out.status) in (1, 2)
        assert float(out.residual) > 1e-10 * float(out.force_scale)
    # a pull the lines do hold (10 MN): converged, balanced
    out = mooring_equilibrium(s, s.loads(body={0: [1e7, 0, 0, 0, 0, 0]}))
    F = np.asarray(out.line_force[:, 1]).sum(0)
    np.testing.assert_allclose(F[0], -1e7, rtol=1e-9)


def test_line_sagging_onto_the_seabed():
    # a chain hung between two points 50 m above the seabed: a short one clears
    # it, a long one would sag through it (not modelled: reported)
    def system(L):
        pts = (
            MooringPoint("fixed", [0.0, 0.0, -100.0]),
            MooringPoint("coupled", [300.0, 0.0, -100.0]),
        )
        return MooringSystem((), pts, [(0, 1)], L, 0.1, 100.0, 1e9, depth=150.0)

    ok = mooring_equilibrium(system(320.0), throw=False)
    assert bool(ok.converged)
    bad = mooring_equilibrium(system(420.0), throw=False)
    assert int(bad.status) == 4 and "below the seabed" in bad.message
    with pytest.raises(Exception, match="hangs below the seabed"):
        mooring_equilibrium(system(420.0))
