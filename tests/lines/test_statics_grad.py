"""Exact derivatives through the catenary statics, checked with numbers:

- a free spar on lines.txt under a surge force and a pitch moment: the
  derivatives of its offset, heave, pitch and line tensions with respect to the
  three line lengths, EA, the mass per length, two anchor coordinates and the
  two loads, against Richardson-extrapolated central differences of re-solved
  equilibria, within 1e-6 relative;
- a coupled spar whose lines carry free buoys (the buoys re-balance): its 6x6
  stiffness equals MoorPy's `getCoupledStiffnessA` (Guyan reduction of the
  analytic stiffness) within 1e-9, and (slow) the derivatives of its surge,
  heave, pitch and surge-pitch entries with respect to the line lengths, EA,
  mass per length, an anchor coordinate and a load on a buoy, against central
  differences within 1e-6.

One compiled function per system gives the outputs and their forward
derivatives along one direction (`jax.jvp`); the differences call it too.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines
from jaxstring.lines import (
    Body,
    MooringPoint,
    MooringSystem,
    coupled_stiffness,
    mooring_equilibrium,
    mooring_system,
)


DECK = lines.case_path("lines.txt")
SPAR = dict(mass=8.066e6, cg=[0.0, 0.0, -78.0], volume=8029.21)


def central(f, theta, i, h):
    """Richardson-extrapolated central difference of f along parameter i."""
    e = np.zeros_like(theta)
    e[i] = h
    d1 = (f(theta + e) - f(theta - e)) / (2 * h)
    d2 = (f(theta + e / 2) - f(theta - e / 2)) / h
    return (4 * d2 - d1) / 3


def check_jvp(fun, theta, steps, rtol):
    """Each column of the Jacobian of `fun` (by jvp) against differences."""
    jvp = jax.jit(lambda th, v: jax.jvp(fun, (th,), (v,)))
    value = lambda th: np.asarray(jvp(jnp.asarray(th), jnp.zeros_like(th))[0])
    y0 = value(theta)
    for i, h in enumerate(steps):
        v = np.zeros_like(theta)
        v[i] = 1.0
        exact = np.asarray(jvp(jnp.asarray(theta), jnp.asarray(v))[1])
        fd = central(value, theta, i, h)
        scale = np.maximum(np.abs(exact), 1e-3 * np.abs(y0) / abs(theta[i] or 1.0))
        err = np.max(np.abs(exact - fd) / scale)
        print(i, err)
        assert err < rtol, (i, exact, fd)
    return y0


# ---------------------------------------------------------------------------
# A free spar


def spar_outputs(theta, system):
    """(surge m, heave m, pitch rad, fairlead tensions of lines 1-2, anchor
    tension of line 1, N) of the spar for
    theta = (L1, L2, L3, EA, w, x anchor 1, y anchor 2, Fx, My)."""
    s = eqx.tree_at(lambda s: s.L, system, theta[:3])
    s = eqx.tree_at(lambda s: s.EA, s, jnp.full(3, theta[3]))
    s = eqx.tree_at(lambda s: s.w, s, jnp.full(3, theta[4]))
    s = eqx.tree_at(lambda s: s.points[0].position, s,
                    s.points[0].position.at[0].set(theta[5]))  # fmt: skip
    s = eqx.tree_at(lambda s: s.points[1].position, s,
                    s.points[1].position.at[1].set(theta[6]))  # fmt: skip
    loads = s.loads(
        body=jnp.zeros((1, 6)).at[0, 0].set(theta[7]).at[0, 4].set(theta[8])
    )
    out = mooring_equilibrium(s, loads, tol=1e-13)
    return jnp.stack(
        [
            out.body_position[0, 0],
            out.body_position[0, 2],
            out.body_rotation[0, 1],
            out.tension[0, 1],
            out.tension[1, 1],
            out.tension[0, 0],
        ]
    )


def test_equilibrium_derivatives():
    spar = Body("free", position=[0.0, 0.0, 0.0], name="spar", **SPAR)
    system = mooring_system(
        DECK, vessel=spar, hydrostatics=np.diag([0, 0, 332941.0, 0, 0, 0])
    )
    t = lines.parse_moordyn(DECK).types["main"]
    theta = np.array([902.2, 902.0, 902.4, t["EA"], t["w"], 853.87, 739.47, 1e6, 2e7])
    steps = [0.05, 0.05, 0.05, 1e5, 0.01, 0.05, 0.05, 5e3, 1e5]
    y0 = check_jvp(lambda th: spar_outputs(th, system), theta, steps, 1e-6)
    assert y0[0] > 10.0  # the spar moved downstream


# ---------------------------------------------------------------------------
# A coupled spar with buoys on its lines


def buoyed_system():
    deck = lines.parse_moordyn(DECK)
    pos = {p["id"]: np.array(p["position"]) for p in deck.points}
    t = deck.types["main"]
    body = Body("coupled", position=[0.0, 0.0, 0.0], name="spar")
    pts = [MooringPoint("fixed", pos[i + 1], name=f"anchor {i + 1}") for i in range(3)]
    for i in range(3):
        a, f = pos[i + 1], pos[i + 4]
        c = a + 0.45 * (f - a)
        c[2] = -200.0
        pts.append(MooringPoint("free", c, 2e3, 10.0, name=f"buoy {i + 1}"))
    pts += [
        MooringPoint("body", pos[i + 4], body=0, name=f"fairlead {i + 1}")
        for i in range(3)
    ]
    attach = [(i, 3 + i) for i in range(3)] + [(3 + i, 6 + i) for i in range(3)]
    L = [450.0] * 3 + [452.2] * 3
    return MooringSystem(
        (body,), pts, attach, L, t["d"], t["w"], t["EA"], depth=320.0, g=9.81
    )


def test_stiffness_with_free_buoys_against_moorpy():
    pytest.importorskip("moorpy")  # the peer module imports it when called
    from jaxstring.testing import moorpy_peer as mp

    s = buoyed_system()
    K, out = coupled_stiffness(s)
    assert s.n_free == 9 and bool(out.converged)
    ms = mp.moorpy_system(s)
    ms.solveEquilibrium(tol=1e-9, maxIter=500)
    np.testing.assert_allclose(
        np.asarray(out.point_position[3:6]),
        np.array([p.r for p in ms.pointList[3:6]]),
        atol=1e-6,
    )
    KA = ms.getCoupledStiffnessA()
    np.testing.assert_allclose(np.asarray(K), KA, rtol=0, atol=1e-9 * np.abs(KA).max())


def stiffness_outputs(theta, system):
    """(K surge, K heave, K pitch, K surge-pitch) of the buoyed spar for
    theta = (L anchor side, L fairlead side, EA, w, x anchor 1, Fz on buoy 1)."""
    L = jnp.concatenate([jnp.full(3, theta[0]), jnp.full(3, theta[1])])
    s = eqx.tree_at(lambda s: s.L, system, L)
    s = eqx.tree_at(lambda s: s.EA, s, jnp.full(6, theta[2]))
    s = eqx.tree_at(lambda s: s.w, s, jnp.full(6, theta[3]))
    s = eqx.tree_at(lambda s: s.points[0].position, s,
                    s.points[0].position.at[0].set(theta[4]))  # fmt: skip
    loads = s.loads(point=jnp.zeros((9, 3)).at[3, 2].set(theta[5]))
    K, _ = coupled_stiffness(s, loads, tol=1e-13)
    return jnp.stack([K[0, 0], K[2, 2], K[4, 4], K[0, 4]])


@pytest.mark.slow
def test_stiffness_derivatives():
    system = buoyed_system()
    t = lines.parse_moordyn(DECK).types["main"]
    theta = np.array([450.0, 452.2, t["EA"], t["w"], 853.87, -2e4])
    steps = [0.05, 0.05, 1e5, 0.01, 0.05, 1e2]
    check_jvp(lambda th: stiffness_outputs(th, system), theta, steps, 1e-6)
