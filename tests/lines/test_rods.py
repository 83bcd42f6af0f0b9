"""Rods (MoorDyn's rigid cylinders) on the earth, checked against MoorDyn 2.7's
rod tests (`rods.cpp`, tolerance 1e-2) and against rigid-body mechanics:

- the loads of a rod against hydrostatics (a vertical rod through the surface,
  a level rod under water) and its mass matrix;
- AddedMass: a buoyant free rod rises at a = (rho V - m) g / (m + rho V Ca),
  every node within MoorDyn's rtol 1e-8, atol 1e-10 m;
- RodPinnedFloating: two buoyant rods pinned to the earth swing up; after 10 s
  end B sits where MoorDyn's does (within 1e-4 m);
- RodHanging: a free rod hung from two ropes stays level (MoorDyn's criteria
  <= 0.01);
- a spinning free rod in vacuum keeps its angular momentum and its centre of
  mass at rest (the gyroscopic terms MoorDyn leaves out);
- a coupled rod follows its prescribed motion.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines
from jaxstring.lines.rods import rod_loads


G = 9.80665
RHO = 1025.0


def _env():
    return js.Environment(g=G, rho_water=RHO)


def test_rod_hydrostatics():
    """A vertical rod with 6 m of its 10 m under water: weight plus the pressure
    on its lower end, rho g A 6, and no side force; a level rod under water:
    weight plus rho g V, no moment; its mass matrix m I + rho V Ca (I - q q^T)
    + 2 rho CaEnd (pi d^3/12) q q^T."""
    d, w, L = 0.5, 80.0, 10.0
    A = math.pi * d**2 / 4
    loads = {"gravity": True, "buoyancy": True}
    rod = lines.Rod([0, 0, -6.0], [0, 0, 4.0], 5, d, w, Ca=1.0, CaEnd=0.5)
    z = jnp.zeros(3)
    out = rod_loads(rod, jnp.array([0, 0, -6.0]), jnp.array([0, 0, 1.0]), z, z,
                    0.0, _env(), loads)  # fmt: skip
    F = np.sum(np.asarray(out.forces), axis=0)
    np.testing.assert_allclose(F, [0, 0, -w * L * G + RHO * G * A * 6.0], rtol=1e-12)
    level = lines.Rod([-5.0, 0, -3.0], [5.0, 0, -3.0], 4, d, w, Ca=1.0, CaEnd=0.5)
    q = jnp.array([1.0, 0, 0])
    out = rod_loads(level, jnp.array([-5.0, 0, -3.0]), q, z, z, 0.0, _env(), loads)
    r, f = np.asarray(out.positions), np.asarray(out.forces)
    np.testing.assert_allclose(
        np.sum(f, 0), [0, 0, (RHO * A - w) * L * G], rtol=1e-12, atol=1e-9
    )
    moment = np.sum(np.cross(r - [0, 0, -3.0], f), 0) + np.asarray(out.moment)
    np.testing.assert_allclose(moment, 0, atol=1e-9)
    Q = np.outer(q, q)
    expect = (w * L * np.eye(3) + RHO * A * L * (np.eye(3) - Q)
              + 2 * RHO * 0.5 * math.pi * d**3 / 12 * Q)  # fmt: skip
    np.testing.assert_allclose(np.sum(np.asarray(out.masses), 0), expect, rtol=1e-12)


def test_tilted_rod_through_the_surface_floats_by_archimedes():
    """A rod through the surface at 20-60 deg from the vertical, end A at 1.3-6 m
    depth: its buoyancy (side buoyancy of the wetted fractions, the submerged end
    cap's pressure) sums to rho g A L_sub upwards, L_sub = -z_A / cos(tilt) its
    submerged length, with no horizontal part, to within the lumping of the
    node crossing the surface: the error falls with the segment count, below
    1e-4 at 128 segments (1e-2 at 8)."""
    import equinox as eqx

    d, w, L = 1.0, 400.0, 9.0
    A = math.pi * d**2 / 4
    z = jnp.zeros(3)
    net = eqx.filter_jit(
        lambda rod, a, q: jnp.sum(
            rod_loads(rod, a, q, z, z, 0.0, _env(), {"buoyancy": True}).forces, 0
        )
    )
    for tilt, zA in ((20.0, -3.0), (45.0, -1.3), (60.0, -3.0)):
        th = math.radians(tilt)
        q = np.array([math.sin(th), 0.0, math.cos(th)])
        a = np.array([0.0, 0.0, zA])
        archimedes = RHO * G * A * (-zA / math.cos(th))
        errors = []
        for N in (8, 32, 128):
            rod = lines.Rod(a, a + L * q, N, d, w)
            F = np.asarray(net(rod, jnp.asarray(a), jnp.asarray(q)))
            errors.append(np.linalg.norm(F - [0.0, 0.0, archimedes]) / archimedes)
        assert errors[0] < 2e-2 and errors[-1] < 1e-4, (tilt, zA, errors)
        assert errors[-1] < errors[1] < errors[0], (tilt, zA, errors)


def test_added_mass_rod_rises():
    """MoorDyn's added-mass test: every node of the level rod at
    -10 + a t^2 / 2 until it nears the surface, a = 3.29619 m/s^2."""
    scene = lines.read_moordyn(
        lines.case_path("rod_tests/AddedMass.txt"), static=False, t1=2.3
    )
    m, V = 200.0, 2 * math.pi * 0.25**2
    a = (RHO * V * G - m * G) / (m + RHO * V)
    ts = np.linspace(0.0, 2.3, 24)
    traj = js.simulate(scene, "tsit5", rtol=1e-10, atol=1e-10, ts=ts)
    assert traj.ok
    z = np.asarray(traj.obs["rod_nodes"][:, :, 2])
    expect = np.broadcast_to((-10 + 0.5 * a * ts**2)[:, None], z.shape)
    np.testing.assert_allclose(z, expect, rtol=1e-8, atol=1e-10)  # MoorDyn's
    assert np.max(np.abs(z - expect)) < 1e-9


@pytest.mark.slow
def test_pinned_floating_rods_swing_up():
    """MoorDyn's pinned-floating test: after 10 s each rod's end B is above its
    pinned end A; MoorDyn's end B: (0.741795, 0, -4.329373) (its RK2, dt 1e-5)."""
    scene = lines.read_moordyn(lines.case_path("RodPinnedFloating.txt"), t1=10.0)
    traj = js.simulate(
        scene, "tsit5", rtol=1e-8, atol=1e-8, ts=np.linspace(0.0, 10.0, 11)
    )
    assert traj.ok
    nodes = np.asarray(traj.obs["rod_nodes"][-1]).reshape(2, 2, 3)
    assert np.all(nodes[:, 1, 2] >= nodes[:, 0, 2])  # MoorDyn's check
    np.testing.assert_allclose(nodes[0, 1], [0.741795, 0, -4.329373], atol=1e-4)
    np.testing.assert_allclose(nodes[1, 1], [0, 0.741795, -4.329373], atol=1e-4)
    np.testing.assert_array_equal(nodes[:, 0], [[0, 0, -5.0]] * 2)


def test_hanging_rod_stays_level():
    """MoorDyn's hanging-rod test: released from its deck pose with the ropes at
    rest around it (the lines' static shape), the rod falls onto the ropes and
    hangs level: (x_A + 10)/20, (x_B - 10)/20, |y|/20, |z_A - z_B|/20 <= 0.01 at
    t = 10 s (MoorDyn: 0.0070, 0.0070, 0, 0.0036; here 0 to rounding: the
    scene is symmetric and so is its motion)."""
    scene = lines.read_moordyn(lines.case_path("RodHanging.txt"), t1=10.0)
    traj = js.simulate(scene, "tsit5", rtol=1e-6, atol=1e-6,
                       ts=np.linspace(0.0, 10.0, 11))  # fmt: skip
    assert traj.ok
    A, B = np.asarray(traj.obs["rod_nodes"][-1])
    crit = [(A[0] + 10) / 20, (B[0] - 10) / 20, abs(A[1]) / 20, abs(B[1]) / 20,
            abs(A[2] - B[2]) / 20]  # fmt: skip
    assert max(crit) <= 0.01 and max(abs(c) for c in crit) < 1e-9
    assert -90.0 < A[2] < -80.0  # it fell onto the ropes


@pytest.mark.slow
@pytest.mark.parametrize(
    "solver, options, within",
    [("kvaerno5", dict(rtol=1e-5, atol=1e-5), 1e-4),
     ("implicit_euler_fixed", dict(rtol=1e-3, atol=1e-3, dt0=0.01), 2e-2)],
)  # fmt: skip
def test_hanging_rod_with_the_stage_newton_solvers(solver, options, within):
    """The hanging rod with the solvers whose Newton matrix is the Jacobian of a
    stage relation (Kvaerno, the default; the fixed-step theta method): the
    rod's rows are the matrix's border and some of their entries are not read
    by the vector field, where the relation keeps its identity. Its ends after
    each second within `within` (m) of Tsit5's at 1e-6, and MoorDyn's level
    criterion. (Every step was rejected when those entries' columns were
    taken as zeros.)"""
    scene = lines.read_moordyn(lines.case_path("RodHanging.txt"), t1=10.0)
    ts = np.linspace(0.0, 10.0, 11)
    ref = js.simulate(scene, "tsit5", rtol=1e-6, atol=1e-6, ts=ts)
    traj = js.simulate(scene, solver, ts=ts, **options)
    assert traj.ok, traj.status
    ends = np.asarray(traj.obs["rod_nodes"])
    assert np.max(np.abs(ends - np.asarray(ref.obs["rod_nodes"]))) < within
    A, B = ends[-1]
    assert abs(A[2] - B[2]) / 20 <= 0.01 and -90.0 < A[2] < -80.0


def test_spinning_rod_keeps_its_angular_momentum():
    """A free rod in vacuum, spinning about an axis that is not principal: its
    centre of mass stays at rest and its angular momentum about it is
    conserved (rigid-body mechanics with the gyroscopic terms)."""
    rod = lines.Rod([0.0, 0, 0], [4.0, 0, 0], 4, 0.3, 50.0, kind="free")
    model = lines.LineNetwork(
        points=(), attach=(), segments=(), L=jnp.zeros(0), d=jnp.zeros(0),
        w=jnp.zeros(0), EA=jnp.zeros(0), BA=jnp.zeros(0), Cd=jnp.zeros(0),
        Ca=jnp.zeros(0), CdAx=jnp.zeros(0), CaAx=jnp.zeros(0), rods=(rod,),
    )  # fmt: skip
    fr = model.topology.frames
    y0 = model.initial_rigid_rows(jnp.zeros(model.state_shape()))
    omega = np.array([0.3, 1.0, 0.5])
    c0 = np.array([2.0, 0, 0])
    v_a = -np.cross(omega, c0)  # the centre of mass at rest
    y0 = y0.at[fr.trans_row[1], 3:].set(v_a).at[fr.rot_rows[1][0], 3:].set(omega)
    scene = js.Scene(model, (), y0, t1=5.0, env=js.Environment(g=0.0))
    ts = np.linspace(0.0, 5.0, 11)
    traj = js.simulate(scene, "tsit5", rtol=1e-10, atol=1e-10, ts=ts)
    assert traj.ok
    nodes = np.asarray(traj.obs["rod_nodes"])
    ys = np.asarray(traj.ys)
    m = 50.0 * np.array([0.5, 1, 1, 1, 0.5])
    a2 = 0.15**2
    H = []
    for k in range(len(ts)):
        c = np.average(nodes[k], axis=0, weights=m)
        np.testing.assert_allclose(c, c0, atol=1e-8)
        w = ys[k, fr.rot_rows[1][0], 3:]
        va = ys[k, fr.trans_row[1], 3:]
        v = va + np.cross(w, nodes[k] - nodes[k][0])
        q = (nodes[k][-1] - nodes[k][0]) / 4.0
        total = 200.0
        inertia = total * (a2 / 4 - 16 / 96) * (np.eye(3) - np.outer(q, q)) + (
            total * a2 / 2 * np.outer(q, q)
        )
        H.append(np.sum(m[:, None] * np.cross(nodes[k] - c, v), 0) + inertia @ w)
    np.testing.assert_allclose(H, np.broadcast_to(H[0], (len(ts), 3)), atol=1e-7)
    assert np.linalg.norm(H[0]) > 10.0


def test_coupled_rod_follows_its_motion():
    """A coupled rod's frame follows its `RigidMotion`: heave 0.5 sin t and roll
    0.2 sin t, end B turned about the moving end A."""

    def pose(t, p):
        s = jnp.sin(t)
        return jnp.stack([0.0 * s, 0.0 * s, p * s, 0.4 * p * s, 0.0 * s, 0.0 * s])

    motion = lines.RigidMotion(fn=pose, params=jnp.asarray(0.5))
    rod = lines.Rod([0.0, 0, -5], [0.0, 2, -5], 2, 0.2, 10.0, kind="coupled",
                    motion=motion)  # fmt: skip
    free = lines.FreePoint(jnp.array([0.0, 10.0, -5.0]), 1.0)
    model = lines.LineNetwork(
        points=(free,), attach=((lines.RodEnd(0, "B"), 0),), segments=(2,),
        L=jnp.array([8.0]), d=jnp.array([0.05]), w=jnp.array([1.0]),
        EA=jnp.array([1e5]), BA=jnp.array([0.0]), Cd=jnp.array([0.0]),
        Ca=jnp.array([0.0]), CdAx=jnp.array([0.0]), CaAx=jnp.array([0.0]),
        rods=(rod,),
    )  # fmt: skip
    y0 = lines.initial_shape(model, (), js.Environment())
    for t in (0.3, 1.1):
        obs = js.Scene(model, (), y0, t1=2.0).observables(y0, t)
        a = np.array([0, 0, -5 + 0.5 * math.sin(t)])
        roll = 0.2 * math.sin(t)
        b = a + 2 * np.array([0, math.cos(roll), math.sin(roll)])
        np.testing.assert_allclose(obs["rod_end_a"][0], a, atol=1e-12)
        np.testing.assert_allclose(obs["rod_nodes"][-1], b, atol=1e-12)
    with pytest.raises(ValueError, match="`motion` is for a 'coupled'"):
        lines.Rod([0.0, 0, -5], [0.0, 2, -5], 2, 0.2, 10.0, motion=motion)


@pytest.mark.slow
def test_rod_output_channels(tmp_path):
    """MoorDyn's rod channels: at rest the pinned rod lying along +x carries its
    buoyancy less its weight, (rho A L - w L) g up, and the moment of that
    force about end A, half a metre away; its axis is 90 deg from vertical.
    Half a second on it has swung over to -x, as MoorDyn's."""
    scene = lines.read_moordyn(lines.case_path("RodPinnedFloating.txt"), t1=0.5)
    traj = js.simulate(scene, "tsit5", rtol=1e-6, atol=1e-6,
                       ts=np.linspace(0.0, 0.5, 3))  # fmt: skip
    out, npz = lines.write_outputs(traj, scene, str(tmp_path / "rpf"))
    with open(out) as f:
        names, units = f.readline().split(), f.readline().split()
    assert names[:4] == ["Time", "ROD1PX", "ROD1PY", "ROD1PZ"]
    assert units[names.index("ROD1RY")] == "(deg)"
    assert units[names.index("ROD2MX")] == "(Nm)"
    ch = np.load(npz)
    Fz = (1000.0 * math.pi * 0.25**2 / 4 - 10.0) * G
    assert ch["ROD1FZ"][0] == pytest.approx(Fz, rel=1e-12)
    assert ch["ROD1MY"][0] == pytest.approx(-0.5 * Fz, rel=1e-12)
    assert ch["ROD2MX"][0] == pytest.approx(0.5 * Fz, rel=1e-12)
    assert ch["ROD1RY"][0] == pytest.approx(90.0) and ch["ROD2RX"][0] == -90.0
    # swung up and over in 0.5 s (MoorDyn's moment then: 191.658 N m)
    assert ch["ROD1N1PZ"][1] > -4.2 and ch["ROD1N1PX"][-1] < -0.99
    assert ch["ROD1MY"][-1] == pytest.approx(191.658, rel=1e-4)
