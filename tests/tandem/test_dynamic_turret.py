"""The FPSO's turret on lumped-mass lines integrated with the vessels
(`with_dynamic_mooring`): the coupled linearisation against the spring of the
lines' own static stiffness, and the motion against the quasi-static lines."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines
from jaxstring.tandem import (
    MooredVessels,
    TurretMooring,
    stability,
    tandem_controlled,
    tandem_equilibria,
    tandem_fishtail,
    tandem_fpso_alone,
    with_dynamic_mooring,
)
from jaxstring.tandem.turret import split_mooring_effects
from jaxstring.tandem.vessels import point_kinematics


@eqx.filter_jit
def _rates_and_jacobian(scene, u):
    f = lambda v: scene.vector_field(0.0, v.reshape(scene.y0.shape)).reshape(-1)
    return f(u), jax.jacfwd(f)(u)


@eqx.filter_jit
def _turret_force(model: MooredVessels, yl, P, effects, env):
    """The lines' x force on the turret at offset P, the lines at rest in yl."""
    net = model.moved(P, jnp.zeros(2))
    st = net._state(0.0, yl, effects, env)
    _, acc, _, _ = net._rates(0.0, yl, st, effects, env)
    fa, fb = net.end_forces(st, acc)
    ib = [k for k, (_, b) in enumerate(net.attach) if b in model.fairleads]
    ia = [k for k, (a, _) in enumerate(net.attach) if a in model.fairleads]
    return fb[jnp.asarray(ib, int)].sum(0)[0] + fa[jnp.asarray(ia, int)].sum(0)[0]


@pytest.mark.slow
def test_coupled_modes_are_the_spring_of_the_lines_stiffness():
    # the FPSO alone heading into the current, its turret on the packaged deck's
    # lines (3 segments a line: 73 state rows) in still water
    sc = with_dynamic_mooring(tandem_fpso_alone(psi0_deg=0.0), segments=3)
    m = sc.model
    assert sc.y0.shape == (1 + m.network.topology.n_state, 6)
    assert sc.structure.border == 1
    # the coupled equilibrium (vessel and lines at rest) by Newton
    u = sc.y0.reshape(-1)
    for _ in range(6):
        r, J = _rates_and_jacobian(sc, u)
        u = u - jnp.linalg.solve(J, r)
    r, J = _rates_and_jacobian(sc, u)
    assert float(jnp.max(jnp.abs(r))) < 1e-8
    eigs = np.linalg.eigvals(np.asarray(J))
    assert np.all(eigs.real < 0)  # stable, lines included
    # the lines' static stiffness at that offset: central differences of the
    # force of the network's own statics (free points re-balanced)
    y = u.reshape(sc.y0.shape)
    yv, yl = m.split(y)
    P, _ = point_kinematics(yv[:3], yv[3:], m.vessels.x_t)
    _, line_eff = split_mooring_effects(sc.effects)
    h = 0.25
    F = []
    for s in (1.0, -1.0):
        Ps = P + jnp.array([s * h, 0.0])
        y_s, _ = lines.equilibrium(
            m.moved(Ps, jnp.zeros(2)), line_eff, sc.env, 0.0, y0=yl,
            free_points="solve",
        )  # fmt: skip
        F.append(float(_turret_force(m, y_s, Ps, line_eff, sc.env)))
    K = -(F[0] - F[1]) / (2 * h)
    assert 3.0e4 < K < 4.5e4  # 3 segments: softer than the catenaries' 43.8 kN/m
    # the spring of that stiffness (no hardening, no damping: the lines damp)
    spring = tandem_fpso_alone(
        psi0_deg=0.0, mooring=TurretMooring(k_m=K, rho_m=1.0e4, c_m=0.0)
    )
    e_s, kind = stability(spring, spring.y0)
    assert kind == "stable"
    slow = eigs[np.abs(eigs) < 0.05]
    assert slow.size == e_s.size == 6
    # weathervaning: the turret's force, not its stiffness
    real = lambda e: np.sort(e[np.abs(e.imag) < 1e-12].real)
    np.testing.assert_allclose(real(slow), real(e_s), rtol=5e-3)
    # surge and sway-yaw pairs: the lines' own inertia (a few percent of the
    # hull's) lowers both frequencies a little
    w_dyn = np.sort(slow.imag[slow.imag > 0])
    w_spr = np.sort(e_s.imag[e_s.imag > 0])
    assert np.all(w_dyn < w_spr)
    np.testing.assert_allclose(w_dyn, w_spr, rtol=3e-2)


def test_bad_dynamic_mooring_input():
    spring = tandem_fpso_alone(psi0_deg=0.0)
    with pytest.raises(ValueError, match="`segments`"):
        with_dynamic_mooring(spring, segments=0)
    with pytest.raises(ValueError, match="`c_m`"):
        with_dynamic_mooring(spring, c_m=-1.0)
    with pytest.raises(ValueError, match="`deck`"):
        with_dynamic_mooring(spring, deck=3)
    with pytest.raises(ValueError, match="`mooring`.*'dynamic'"):
        tandem_equilibria(mooring="dynamic")
    with pytest.raises(ValueError, match="`K_I`"):
        tandem_controlled(mooring="dynamic", K_I=1e-5)
    with pytest.raises(ValueError, match="`hawser`"):
        tandem_fishtail(mooring="dynamic", hawser="line")
    with pytest.raises(ValueError, match="needs a tandem or FPSO-alone scene"):
        with_dynamic_mooring(js.string_pendulum())


@pytest.mark.slow
def test_dynamic_lines_follow_the_quasi_static_lines():
    # 600 s of the FPSO alone turned 10 deg off the current: the deck's 20
    # segments a line integrated with the hull (3192 state rows, a band with
    # the hull's row as its border) against the quasi-static catenaries with
    # the same turret damping; the lines in still water
    qs = tandem_fpso_alone(mooring="lines", psi0_deg=10.0, t1=600.0)
    dyn = with_dynamic_mooring(qs, c_m=6.0e5)
    ts = jnp.linspace(0.0, 600.0, 11)
    a = js.simulate(dyn, "kvaerno5", rtol=1e-6, atol=1e-6, ts=ts)
    b = js.simulate(qs, "tsit5", rtol=1e-8, atol=1e-8, ts=ts)
    assert a.status == "success"
    ya, yb = np.asarray(a.ys)[:, 0], np.asarray(b.ys)
    # the hull swings 1.5 deg and surges 1 m: the two agree to the lumped
    # lines' stiffness (2.5 % above the catenaries' at 20 segments)
    assert np.ptp(yb[:, 2]) > np.radians(1.0)
    np.testing.assert_allclose(ya[:, 2], yb[:, 2], atol=np.radians(0.15))
    np.testing.assert_allclose(ya[:, :2], yb[:, :2], atol=0.15)


@pytest.mark.slow
def test_dynamic_fishtail_runs():
    sc = tandem_fishtail(mooring="dynamic", t1=600.0)
    assert isinstance(sc.model, MooredVessels)
    traj = js.simulate(sc, "kvaerno5", rtol=1e-6, atol=1e-6, ts=jnp.linspace(0, 600, 7))
    assert traj.status == "success"
    ys = np.asarray(traj.ys)
    assert np.all(np.isfinite(ys))
    assert ys[-1, 1, 2] > ys[0, 1, 2]  # the shuttle's yaw grows (fishtail onset)
    # the FPSO, at the quasi-static lines' equilibrium, moves by decimetres
    assert np.max(np.abs(ys[:, 0, :2] - ys[0, 0, :2])) < 1.0
