"""The lumped-mass-and-spring (LMS) tether against the inextensible chain.

`LmsTether` replaces every rigid link of `ExactTether` by a linear spring of
stiffness k (tension k (l - g)/L_link). In a static case it must reproduce the
inextensible chain's shape, with a length error that falls as 1/k; without drag
and damping it must conserve kinetic + elastic + gravity/buoyancy energy.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import jaxstring as js
from jaxstring import UniformCurrent
from jaxstring._environment import Environment
from jaxstring._scene import Scene
from jaxstring.chain import Buoyancy, Drag, Gravity
from jaxstring.tether import (
    ExactTether,
    FixedEnd,
    LmsTether,
    arc_state,
    hanging_state,
)


G = 9.81
RHO = 1024.0
D_CABLE = 0.01  # m
MPL = 0.4  # kg/m: net weight (0.4 - 0.080) g = 3.1 N/m in water
EFFECTS = (Gravity(), Buoyancy(), Drag(CdAx=0.1, Cd=1.0))


def _ends(span):
    return dict(root=FixedEnd(jnp.zeros(3)), fast=FixedEnd(jnp.array([span, 0, 0.0])))


# ---------------------------------------------------------------------------
# Static shape in a uniform current


def test_lms_settles_to_the_inextensible_shape_in_current():
    # A cable hanging from a fixed root with a free end, released straight down
    # into a 0.6 m/s current: drag carries both chains to the same steady shape
    # (about 7 m downstream at the free end). With k_lms = 4e5 N (the scene
    # default, 40 k) the springs stretch by ~1e-4 of L, so node by node the two
    # shapes agree to far better than 1 % of the line length (measured 6.5e-5).
    N, L = 8, 16.0
    env = Environment(rho_water=RHO, current=UniformCurrent((-0.6, 0.0, 0.0)))
    ts = jnp.array([150.0, 200.0])
    final = {}
    for cls, kw in ((ExactTether, {}), (LmsTether, {"k": 4e5})):
        model = cls(L=L, d=D_CABLE, mass_per_length=MPL, N=N, **kw)
        scene = Scene(
            model=model, effects=EFFECTS, y0=hanging_state(model), t1=200.0, env=env
        )
        traj = js.simulate(
            scene, "dopri5", rtol=1e-8, atol=1e-8, ts=ts, max_steps=10**6
        )
        assert traj.ok, traj.status
        pos = np.asarray(traj.positions)
        # Steady: the last 50 s move no node by more than 1e-4 of L.
        assert np.max(np.abs(pos[1] - pos[0])) < 1e-4 * L
        final[cls.__name__] = pos[1]
    exact, lms = final["ExactTether"], final["LmsTether"]
    assert -exact[-1, 0] > 5.0  # a real deflection downstream (current along -x)
    dev = np.linalg.norm(lms - exact, axis=1) / L
    assert np.max(dev) < 0.01, dev


# ---------------------------------------------------------------------------
# Length error vs spring stiffness


def _residual(p, args):
    """Element forces (N) at positions `p` and zero velocity."""
    model, env = args
    y = jnp.concatenate([p, jnp.zeros_like(p)], axis=1)
    return model.vector_field(0.0, y, EFFECTS, env)[:, 3:] * model.inertia(env)


@eqx.filter_jit
def _newton(model, p0, env):
    sol = optx.root_find(
        _residual,
        optx.Newton(rtol=1e-13, atol=1e-13),
        p0,
        (model, env),
        max_steps=100,
        throw=False,
    )
    return sol.value, jnp.max(jnp.abs(_residual(sol.value, (model, env))))


def _static(model, p0, env):
    """Static shape: Newton (optimistix) on the element forces at zero velocity."""
    p, res = _newton(model, p0, env)
    assert float(res) < 1e-8, float(res)  # N, on element loads of ~10 N
    return np.asarray(p)


def _stretched_length(p, span):
    X = np.concatenate([np.zeros((1, 3)), p, [[span, 0.0, 0.0]]])
    return float(np.sum(np.linalg.norm(np.diff(X, axis=0), axis=1)))


def test_lms_length_error_falls_as_one_over_k():
    # A cable between two fixed points (16 m of cable over a 12 m span), sagging
    # under its net weight and pushed sideways by a 0.5 m/s cross current. The
    # springs' total stretch is sum_j T_j L_link / k: proportional to 1/k as long
    # as the tensions do not change with the stretch. Here they do (a longer
    # cable sags more and carries less), so the ratio is only about 10 for a 10x
    # stiffer line, approaching 10 as k grows, and k times the error tends to
    # L_link sum_j T_j of the inextensible chain.
    N, L, span = 8, 16.0, 12.0
    env = Environment(rho_water=RHO, current=UniformCurrent((0.0, 0.5, 0.0)))
    exact = ExactTether(L=L, d=D_CABLE, mass_per_length=MPL, N=N, **_ends(span))
    start = jnp.asarray(arc_state(exact, bulge=(0.0, 0.5, -1.0))[:, :3])
    p_exact = _static(exact, start, env)
    assert abs(_stretched_length(p_exact, span) - L) < 1e-10 * L
    y_exact = jnp.concatenate([jnp.asarray(p_exact), jnp.zeros((N, 3))], axis=1)
    T = np.asarray(exact.observables(0.0, y_exact, EFFECTS, env)["tension"])
    assert np.min(T) > 10.0  # a loaded case: 17-31 N in the links
    limit = float(exact.link_length) * float(np.sum(T))  # k * error as k -> inf, N m

    ks = (1e3, 1e4, 1e5)  # N; strains of ~3 %, 0.3 %, 0.03 %
    errors = []
    for k in ks:
        lms = LmsTether(L=L, d=D_CABLE, mass_per_length=MPL, N=N, k=k, **_ends(span))
        p = _static(lms, jnp.asarray(p_exact), env)
        errors.append(_stretched_length(p, span) - L)
        # The model's own length error (relative, unstretched minus stretched).
        y = jnp.concatenate([jnp.asarray(p), jnp.zeros((N, 3))], axis=1)
        obs = lms.observables(0.0, y, EFFECTS, env)
        np.testing.assert_allclose(-float(obs["length_error"]) * L, errors[-1], 1e-9)
    errors = np.asarray(errors)
    assert np.all(errors > 0)
    r1, r2 = errors[0] / errors[1], errors[1] / errors[2]
    # Measured: 9.72 and 9.97.
    assert 8.0 < r1 < 12.0 and 8.0 < r2 < 12.0, (r1, r2)
    assert abs(r2 - 10.0) < abs(r1 - 10.0)
    # k * error -> L_link sum T: 3 % below the limit at k = 1e3, 0.04 % at 1e5.
    rel = np.abs(np.asarray(ks) * errors - limit) / limit
    assert rel[2] < 1e-3 and rel[2] < rel[1] < rel[0], rel


# ---------------------------------------------------------------------------
# Energy


def _swing(c=0.0, k=4e4, t1=2.0):
    """A heavy cable between two fixed points released from a sideways arc in
    still water (weight and buoyancy only, no drag)."""
    N, L, span = 9, 12.0, 8.0
    model = LmsTether(L=L, d=D_CABLE, mass_per_length=0.5, N=N, k=k, c=c, **_ends(span))
    env = Environment(rho_water=RHO)
    y0 = arc_state(model, bulge=(0.0, 1.0, 0.0))
    scene = Scene(model=model, effects=(Gravity(), Buoyancy()), y0=y0, t1=t1, env=env)
    traj = js.simulate(
        scene, "dopri5", rtol=1e-10, atol=1e-10, ts=jnp.linspace(0.0, t1, 81)
    )
    assert traj.ok, traj.status
    # Energy from the state and the documented parameters: element inertia
    # mu = m_e + C_a rho Q_e (C_a = 1), net weight (m_e - rho Q_e) g, link springs
    # of energy k (l - L_link)^2 / (2 L_link) with L_link = L/(N + 1).
    l_e, L_link = L / N, L / (N + 1)
    Q = math.pi * D_CABLE**2 / 4 * l_e
    m_e = 0.5 * l_e
    mu = m_e + RHO * Q
    P, V = np.asarray(traj.positions), np.asarray(traj.velocities)
    kinetic = 0.5 * mu * np.sum(V**2, axis=(1, 2))
    gravity = (m_e - RHO * Q) * G * np.sum(P[:, :, 2], axis=1)
    n = len(P)
    root = np.zeros((n, 1, 3))
    fast = np.broadcast_to([span, 0.0, 0.0], (n, 1, 3))
    X = np.concatenate([root, P, fast], axis=1)
    l = np.linalg.norm(np.diff(X, axis=1), axis=2)
    elastic = 0.5 * k / L_link * np.sum((l - L_link) ** 2, axis=1)
    return traj, kinetic, gravity + elastic, elastic


def test_lms_conserves_energy_without_drag_and_damping():
    # Measured drift: 2e-13 of the largest kinetic energy (rtol = atol = 1e-10).
    traj, kinetic, potential, elastic = _swing()
    E = kinetic + potential
    assert kinetic.max() > 50.0  # J: it really swings
    assert elastic.max() > 1e-3 * kinetic.max()  # and the springs take part
    drift = np.max(np.abs(E - E[0])) / kinetic.max()
    assert drift < 1e-6, drift
    # The model's energy observable is the same sum.
    model_E = np.asarray(traj.energy)
    assert np.max(np.abs(model_E - E)) < 1e-9 * kinetic.max()


def test_lms_link_damping_only_dissipates():
    # The same swing with damped links (c = 200 N s): energy never rises and the
    # axial vibration it damps is a small share of the motion (measured loss:
    # 2.9e-4 of the largest kinetic energy in 2 s).
    _, kinetic, potential, _ = _swing(c=200.0)
    E = kinetic + potential
    assert np.all(np.diff(E) <= 1e-9 * kinetic.max())
    loss = (E[0] - E[-1]) / kinetic.max()
    assert 1e-4 < loss < 0.05, loss
