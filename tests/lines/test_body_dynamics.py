"""Floating bodies (MoorDyn's BODIES) checked against MoorDyn 2.7's body tests
(`bodies.cpp`, with their tolerances), against MoorDyn's own trajectories of
the same decks, and against rigid-body mechanics:

- excentric body: two free bodies whose mass sits away from their reference
  point (in two points; in a rod) orbit at radius 10 m and 0.2 rad/s (MoorDyn's
  criteria: both within 1e-6 relative);
- rotating body: a free body turned by a line pulled round by a coupled point
  ends up turned by -90 deg about x (MoorDyn's: the point on the body within
  atol 0.15 + rtol 0.1 of where it should be after each leg; the final
  rotation's axis within 0.15 of x, its angle within 10 deg of 90);
- pinned body: a pendulum (a rod on a massless pinned body) on a cart that
  accelerates at a swings about atan(-a/g) (MoorDyn's criterion: the mean roll
  within 0.001 rad of it); its roll follows MoorDyn's;
- body drag: a free body falls onto its drag; its fall and its net force follow
  MoorDyn's (RK2, dtM 2 ms);
- bodies and rods: a free body carrying a fixed and a pinned rod, moored by
  three lines and a buoyed cable, sinks as MoorDyn's does (slow);
- a coupled body turning at a constant rate: its point carries the line's end,
  and its net force is the line's pull less the inertia of the line's end
  node, with the moment of it about the reference point;
- a free body spinning about an axis that is not principal keeps its angular
  momentum and kinetic energy (the gyroscopic terms MoorDyn leaves out);
- the sensitivity of a body's response to its mass by forward-mode autodiff
  through the integration agrees with central differences.
"""

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines
from jaxstring._fit import SolveConfig, solve
from jaxstring.chain import FixedEnd, PrescribedEnd
from jaxstring.lines import models


G = 9.80665
# MoorDyn 2.7's outputs on these decks (data/README.md)
MOORDYN = np.load(os.path.join(os.path.dirname(__file__), "data", "moordyn_bodies.npz"))


def _deck(name):
    return lines.case_path(f"body_tests/{name}")


def _quaternion(R):
    """Unit quaternion (w, x, y, z), w >= 0, of a rotation matrix."""
    w = 0.5 * math.sqrt(max(1.0 + np.trace(R), 0.0))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return np.concatenate([[w], v / (4 * w)])


# Slow: a free body's rigid-body dynamics are checked in the default run by the
# spinning body (angular momentum, energy) and by MoorDyn's body-drag case.
@pytest.mark.slow
def test_excentric_body_orbits():
    """MoorDyn's excentric-body test: each body starts with its reference point
    moving at (0, 0, 2) m/s and turning at 0.2 rad/s about x, so that its mass
    (two 20 kg points; a 4 m rod) at (0, 0, 20) stays at rest and the reference
    point orbits it: radius 10 m and angle 0.2 t within 1e-6 relative after
    every 0.25 s (measured: 6e-13 and 9e-12)."""
    scene = lines.read_moordyn(_deck("orbitalBody.txt"), static=False, t1=10.0)
    fr = scene.model.topology.frames
    y0 = scene.y0
    for f in (1, 2):
        y0 = y0.at[fr.trans_row[f], 3:].set(jnp.array([0.0, 0.0, 2.0]))
        y0 = y0.at[fr.rot_rows[f][0], 3:].set(jnp.array([0.2, 0.0, 0.0]))
    scene = eqx.tree_at(lambda s: s.y0, scene, y0)
    ts = np.arange(1, 41) * 0.25
    traj = js.simulate(scene, "tsit5", rtol=1e-12, atol=1e-12, ts=ts)
    assert traj.ok
    p = np.asarray(traj.obs["body_position"])  # (T, 2, 3)
    q = (p - [0.0, 0.0, 20.0]) / 10.0
    err_r = np.linalg.norm(p - [0.0, 0.0, 20.0], axis=-1) - 10.0
    err_w = np.arctan2(q[..., 2], q[..., 1]) / ts[:, None] - 0.2
    assert np.max(np.abs(err_r)) <= 1e-6 * 10.0  # MoorDyn's
    assert np.max(np.abs(err_w)) <= 1e-6 * 0.2  # MoorDyn's
    assert np.max(np.abs(err_r)) < 1e-10 and np.max(np.abs(err_w)) < 1e-10


def _rotating_body_path():
    """Coupled point 9 of MoorDyn's rotating-body test: three quarter turns of
    radius 2 m about the body's centre c in 2 s each (sampled every 0.1 s, as
    the test does), each followed by 0.5 s held 2.05 m from c; the times at
    the ends of the holds and where the point on the body should be then."""
    c = np.array([0.0, 0.0, 5.0])
    legs = [lambda a: (math.cos(a), 0, math.sin(a)),
            lambda a: (0, math.sin(a), math.cos(a)),
            lambda a: (math.sin(a), math.cos(a), 0)]  # fmt: skip
    ends = [(0, 0, 1.0), (0, 1.0, 0), (1.0, 0, 0)]
    T, X, checks = [0.0], [c + [2.0, 0, 0]], []
    t = 0.1
    for leg, e in zip(legs, ends):
        for i in range(21):
            T.append(t + 0.1 * i)
            X.append(c + 2.0 * np.array(leg(0.25 * math.pi * 0.1 * i)))
        t += 2.0
        T.append(t + 0.1)
        X.append(c + 2.05 * np.array(e))
        t += 0.5
        checks.append(t)
    T.append(t + 0.1)
    X.append(X[-1])
    return c, np.array(T), np.array(X), np.array(checks), np.array(ends)


@pytest.mark.slow
def test_rotating_body():
    """MoorDyn's rotating-body test (MoorDyn gives (-0.02, 0, 1.01),
    (0.01, 1.01, 0.00), (1.01, 0.08, -0.02) and a turn of 89.7 deg about
    (-0.998, -0.030, 0.053); here (0.03, 0, 1.00), (-0.04, 1.00, 0.02),
    (1.01, -0.08, -0.03) and 91.4 deg about (-0.998, 0.054, -0.022))."""
    c, T, X, checks, ends = _rotating_body_path()
    scene = lines.read_moordyn(_deck("rotatingBody.txt"), static=False,
                               motion={9: PrescribedEnd(T, X)},
                               t1=float(checks[-1]))  # fmt: skip
    traj = js.simulate(scene, "tsit5", rtol=1e-8, atol=1e-8, ts=checks)
    assert traj.ok
    p = np.asarray(traj.obs["body_position"][:, 0])
    R = np.asarray(traj.obs["body_rotation"][:, 0])
    point8 = p + R @ np.array([1.0, 0.0, 0.0])
    for k in range(3):
        np.testing.assert_allclose(point8[k] - c, ends[k], rtol=0.1, atol=0.15)
    q = _quaternion(R[-1])
    angle = math.degrees(2 * math.acos(q[0]))
    axis = q[1:] / math.sqrt(1 - q[0] ** 2)
    assert abs(axis[0]) > 0.85 and abs(axis[1]) < 0.2 and abs(axis[2]) < 0.2
    assert abs(((angle + 180) % 360 - 180) - 90) < 10
    assert axis[0] < 0  # about -x, as MoorDyn's


def test_pinned_body_swings_about_the_cart_angle():
    """MoorDyn's pinned-body test: a massless pinned body carrying a 10 m rod
    (3 segments, 50 t) in vacuum, its pin moved at a = 0.5 m/s^2 along y: the
    rod swings between 0 and 2 atan(-a/g); the mean roll over two swings
    (sampled every 0.01 s until the fourth turning point after 0.3 s) within
    0.001 rad of atan(-a/g) (MoorDyn: 5.2e-5; here 5.2e-5), and the roll within
    2e-5 rad of MoorDyn's at every sample (measured 4.6e-6: MoorDyn's RK2 with
    a 1 ms step); the pin force within 30 N of MoorDyn's."""
    a = 0.5
    motion = lines.RigidMotion(
        fn=lambda t, acc: jnp.stack([0 * t, 0.5 * acc * t**2, 0 * t, 0 * t, 0 * t,
                                     0 * t]),
        params=jnp.asarray(a),
    )  # fmt: skip
    scene = lines.read_moordyn(_deck("pinnedBody.txt"), static=False,
                               motion={"body1": motion}, t1=13.5)  # fmt: skip
    ts = 0.01 * np.arange(1, 1351)
    traj = js.simulate(scene, "tsit5", rtol=1e-9, atol=1e-9, ts=ts)
    assert traj.ok
    roll = np.asarray(traj.obs["body_angles"][:, 0, 0])
    np.testing.assert_allclose(
        np.asarray(traj.obs["body_position"][:, 0]),
        np.stack([0 * ts, 0.5 * a * ts**2, 0 * ts - 5.0], 1), atol=1e-12,
    )  # fmt: skip
    slope = np.diff(roll)
    turns = np.nonzero(slope[1:] * slope[:-1] < 0)[0] + 2
    n = turns[turns >= 30][3] + 1
    theta = math.atan(-a / G)
    assert abs(np.mean(roll[:n]) - theta) <= 0.001  # MoorDyn's
    assert abs(np.mean(roll[:n]) - theta) < 1e-4
    assert np.min(roll) == pytest.approx(2 * theta, abs=2e-4)
    md = MOORDYN["pinned_roll"]
    assert np.max(np.abs(roll[: len(md)] - md)) < 2e-5
    # the force the pin takes (MoorDyn's getFnet: force less the inertia force,
    # no moment), after MoorDyn's start-up of the pin acceleration (1 s), within
    # 30 N of MoorDyn's over a swing of 5e4 N (measured 11 N across, 1.6 N
    # vertical, of 4.9e5 N)
    F = np.asarray(traj.obs["body_force"][:, 0])
    md_f = MOORDYN["pinned_f"]
    n = len(md_f)
    assert np.all(F[:, 3:] == 0)
    np.testing.assert_allclose(F[99:n, :3], md_f[99:], atol=30.0)


def test_body_drag_and_output_channels(tmp_path):
    """MoorDyn's body-drag test (a free body pitched by -90 deg with drag on
    all six axes falls at nearly its terminal speed; MoorDyn's test checks only
    that it runs): the body's height and speed within 2e-4 m and 5e-5 m/s of
    MoorDyn's every 0.1 s for 5 s (measured 7e-5 and 2e-5, MoorDyn's RK2 with a
    2 ms step), its net force (MoorDyn's getFnet) within 5e-3 N after the first
    second (measured 7e-4 N); the BODY1 channels in the .out and .npz files."""
    tint = MOORDYN["drag_t"]
    scene = lines.read_moordyn(_deck("bodyDrag.txt"), static=False,
                               t1=float(tint[-1]))  # fmt: skip
    traj = js.simulate(scene, "tsit5", rtol=1e-9, atol=1e-9, ts=tint)
    assert traj.ok
    obs = traj.obs
    p, v = (
        np.asarray(obs["body_position"][:, 0]),
        np.asarray(obs["body_velocity"][:, 0]),
    )
    np.testing.assert_allclose(p, MOORDYN["drag_r"][:, :3], atol=2e-4)
    np.testing.assert_allclose(v, MOORDYN["drag_rd"][:, :3], atol=5e-5)
    ang = np.asarray(obs["body_angles"][:, 0])
    np.testing.assert_allclose(ang, MOORDYN["drag_r"][:, 3:], atol=1e-12)
    F = np.asarray(obs["body_force"][:, 0])
    late = tint >= 1.0
    np.testing.assert_allclose(F[late], MOORDYN["drag_f"][late], atol=5e-3)
    out, npz = lines.write_outputs(traj, scene, tmp_path / "drag")
    with open(out) as f:
        names = f.readline().rstrip("\n").split("\t")
        units = f.readline().rstrip("\n").split("\t")
    assert names[units.index("(deg)")] == "BODY1RX"
    for name in ("BODY1PZ", "BODY1RY", "BODY1VZ", "BODY1RVX", "BODY1AZ",
                 "BODY1RAX", "BODY1FZ", "BODY1MX", "BODY1TEN"):  # fmt: skip
        assert name in names
    ch = np.load(npz)
    np.testing.assert_allclose(ch["BODY1PZ"], p[:, 2])
    np.testing.assert_allclose(ch["BODY1RY"], -90.0, atol=1e-10)
    np.testing.assert_allclose(ch["BODY1TEN"], np.abs(F[:, 2]))


# MoorDyn 2.7's body height in BodiesAndRods.dat every 0.1 s from 0.1 s to 1 s
# (after its initial-condition solve of the lines, 0.12 s), m
BODIES_AND_RODS_Z = [-0.0501960165, -0.197000114, -0.441306318, -0.782648719,
                     -1.22039236, -1.75338574, -2.37900287, -3.08014295,
                     -3.82895879, -4.59655578]  # fmt: skip


@pytest.mark.slow
def test_bodies_and_rods_sinks_as_moordyn():
    """MoorDyn's bodies-and-rods test (it checks that 1 s runs and stays
    finite): the 1e6 kg body with its two rods (one fixed, one pinned to it)
    sinks within 1e-2 m of MoorDyn's height every 0.1 s (measured 7e-3 m at
    1 s, from the lines' catenary start where MoorDyn first relaxes them) and
    stays level (pitch below 1e-3 rad; MoorDyn 5e-5)."""
    scene = lines.read_moordyn(lines.case_path("BodiesAndRods.dat"), t1=1.0,
                               static=False)  # fmt: skip
    ts = np.linspace(0.1, 1.0, 10)
    traj = js.simulate(scene, "tsit5", rtol=1e-6, atol=1e-6, ts=ts)
    assert traj.ok
    z = np.asarray(traj.obs["body_position"][:, 0, 2])
    np.testing.assert_allclose(z, BODIES_AND_RODS_Z, atol=1e-2)
    assert np.all(np.isfinite(np.asarray(traj.obs["rod_nodes"])))
    assert np.max(np.abs(np.asarray(traj.obs["body_angles"][:, 0]))) < 1e-3


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, base, sign",
    [("mass", 10.0, -1.0), pytest.param("CdA", 1.0, 1.0, marks=pytest.mark.slow)],
)
def test_body_gradient_matches_central_differences(name, base, sign):
    """d z(t = 0.5 s)/d p of the falling drag body for its mass (p = m) and its
    drag areas (p scales every CdA), forward-mode autodiff through the
    integration against central differences (h = 1e-3 p): within 1e-5 relative
    (measured 4e-8 for the mass). Heavier falls further, more drag less far."""
    scene = lines.read_moordyn(_deck("bodyDrag.txt"), static=False, t1=0.5)
    config = SolveConfig(solver="tsit5", rtol=1e-11, atol=1e-11,
                         ts=jnp.array([0.5]), adjoint="forward")  # fmt: skip
    CdA0 = scene.model.bodies[0].CdA

    def z(p):
        if name == "mass":
            s = eqx.tree_at(lambda s: s.model.bodies[0].mass, scene, p)
        else:
            s = eqx.tree_at(lambda s: s.model.bodies[0].CdA, scene, p * CdA0)
        return solve(s, config).obs["body_position"][-1, 0, 2]

    dz = float(jax.jacfwd(z)(jnp.asarray(base)))
    h = 1e-3 * base
    fd = (float(z(jnp.asarray(base + h))) - float(z(jnp.asarray(base - h)))) / (2 * h)
    assert sign * dz > 0
    assert abs(dz - fd) <= 1e-5 * abs(fd)


def test_coupled_body_force_is_the_line_pull_less_inertia():
    """A coupled body turning about z at 0.2 rad/s about its reference point
    (1, 2, -3) with a point 10 m out, a line (2 segments, EA 1e4 N, 1 kg/m)
    from it to an anchor, no gravity, drag or added mass: the line's end node
    is at the point, the body's angles are (0, 0, 0.2 t) and its net force is
    T u + m_end omega^2 r (the pull of the first segment, less the inertia of
    the end node's w L / 4 in its circle), with the moment r x F (MoorDyn's
    getFnet of a coupled body)."""
    w_rate, EA, L, w = 0.2, 1e4, 15.0, 1.0
    motion = lines.RigidMotion(
        fn=lambda t, om: jnp.stack([0 * t, 0 * t, 0 * t, 0 * t, 0 * t, om * t]),
        params=jnp.asarray(w_rate),
    )
    one = lambda v: jnp.array([v])  # noqa: E731
    model = lines.LineNetwork(
        points=(lines.BodyPoint(0, jnp.array([10.0, 0, 0])),
                FixedEnd(jnp.array([31.0, 2.0, -3.0]))),
        attach=((0, 1),), segments=(2,), L=one(L), d=one(0.1), w=one(w),
        EA=one(EA), BA=one(0.0), Cd=one(0.0), Ca=one(0.0), CdAx=one(0.0),
        CaAx=one(0.0), bodies=(lines.Body("coupled", [1.0, 2.0, -3.0]),),
        body_motions=(motion,),
    )  # fmt: skip
    t = 1.3
    r = 10.0 * np.array([math.cos(w_rate * t), math.sin(w_rate * t), 0.0])
    P = np.array([1.0, 2.0, -3.0]) + r
    mid = np.array([31.0, 2.0, -3.0]) + 0.4 * (P - np.array([31.0, 2.0, -3.0]))
    y = jnp.zeros(model.state_shape()).at[0, :3].set(jnp.asarray(mid))
    obs = js.Scene(model, (), y, env=js.Environment(g=0.0), t1=2.0).observables(y, t)
    np.testing.assert_allclose(np.asarray(obs["nodes"][0]), P, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(obs["body_angles"][0]),
                               [0, 0, w_rate * t], atol=1e-14)  # fmt: skip
    np.testing.assert_allclose(np.asarray(obs["body_omega"][0]), [0, 0, w_rate],
                               atol=1e-14)  # fmt: skip
    seg = np.linalg.norm(mid - P)
    T = EA * (seg - L / 2) / (L / 2)
    F = T * (mid - P) / seg + (w * L / 4) * w_rate**2 * r
    F6 = np.asarray(obs["body_force"][0])
    np.testing.assert_allclose(F6[:3], F, rtol=1e-12)
    np.testing.assert_allclose(F6[3:], np.cross(r, F), rtol=1e-12)


def test_spinning_body_keeps_its_angular_momentum():
    """A free body in vacuum (inertia (2, 5, 9) kg m^2 about a centre of gravity
    off its reference point, turned by (0.3, -0.2, 0.5) rad), spinning about an
    axis that is not principal, its centre of gravity at rest: over 5 s its
    angular momentum R I R^T omega and kinetic energy stay within 1e-8
    relative, its centre of gravity within 1e-9 m of where it was."""
    cg = np.array([0.5, -0.2, 0.1])
    body = lines.Body("free", [1.0, 2.0, -3.0], [0.3, -0.2, 0.5], mass=4.0,
                      cg=cg, inertia=[2.0, 5.0, 9.0])  # fmt: skip
    model = _network((), (body,))
    fr = model.topology.frames
    y0 = model.initial_rigid_rows(jnp.zeros(model.state_shape()))
    omega = np.array([0.4, 1.0, -0.7])
    R0 = np.asarray(lines.rotation_matrix(jnp.array([0.3, -0.2, 0.5])))
    c0 = np.array([1.0, 2.0, -3.0]) + R0 @ cg
    v0 = -np.cross(omega, R0 @ cg)  # the centre of gravity at rest
    y0 = y0.at[fr.trans_row[1], 3:].set(jnp.asarray(v0))
    y0 = y0.at[fr.rot_rows[1][0], 3:].set(jnp.asarray(omega))
    scene = js.Scene(model, (), y0, t1=5.0, env=js.Environment(g=0.0))
    ts = np.linspace(0.0, 5.0, 11)
    traj = js.simulate(scene, "tsit5", rtol=1e-11, atol=1e-11, ts=ts)
    assert traj.ok
    R = np.asarray(traj.obs["body_rotation"][:, 0])
    w = np.asarray(traj.obs["body_omega"][:, 0])
    p = np.asarray(traj.obs["body_position"][:, 0])
    Iw = np.einsum("tij,j,tkj,tk->ti", R, [2.0, 5.0, 9.0], R, w)
    H = Iw  # about the centre of gravity, which is at rest
    E = 0.5 * np.einsum("ti,ti->t", w, Iw)
    np.testing.assert_allclose(
        H, np.broadcast_to(H[0], H.shape), rtol=0, atol=1e-8 * np.linalg.norm(H[0])
    )
    np.testing.assert_allclose(E, E[0], rtol=1e-8)
    c = p + np.einsum("tij,j->ti", R, cg)
    np.testing.assert_allclose(c, np.broadcast_to(c0, c.shape), atol=1e-9)
    assert np.max(np.abs(w - omega)) > 0.1  # it does precess


def _network(points, bodies=(), body_motions=()):
    z = jnp.zeros(0)
    return lines.LineNetwork(
        points=points, attach=(), segments=(), L=z, d=z, w=z, EA=z, BA=z, Cd=z,
        Ca=z, CdAx=z, CaAx=z, bodies=bodies, body_motions=body_motions,
    )  # fmt: skip


def test_body_bad_input():
    """Bad bodies, points on bodies and body motions raise ValueErrors that
    name the argument, the value and the valid range."""
    body = lines.Body("free", [0.0, 0, 0], mass=1.0)
    with pytest.raises(ValueError, match=r"`body` must be an integer >= 0; got -1"):
        lines.BodyPoint(-1, jnp.zeros(3))
    with pytest.raises(ValueError, match="`position`"):
        lines.BodyPoint(0, jnp.zeros(2))
    with pytest.raises(ValueError, match="`mass`"):
        lines.BodyPoint(0, jnp.zeros(3), mass=-1.0)
    with pytest.raises(ValueError, match=r"`points\[0\].body` .*\(0\.\.0\); got 1"):
        _network((lines.BodyPoint(1, jnp.zeros(3)),), (body,))
    with pytest.raises(ValueError, match="`bodies` is empty"):
        _network((lines.BodyPoint(0, jnp.zeros(3)),))
    with pytest.raises(ValueError, match="`bodies` must be a tuple of Bodies"):
        _network((), ("body",))
    motion = lines.RigidMotion([0.0, 1.0], np.zeros((2, 6)))
    with pytest.raises(ValueError, match=r"one entry per body \(1\); got 2"):
        _network((), (body,), (None, None))
    with pytest.raises(ValueError, match="of a coupled or pinned body; .* 'free'"):
        _network((), (body,), (motion,))
    deck = _deck("rotatingBody.txt")
    with pytest.raises(ValueError, match="`motion` key 'ship1' is not valid"):
        lines.read_moordyn(deck, motion={"ship1": motion}, static=False)
    with pytest.raises(ValueError, match=r"not coupled .*\('point', 9\)"):
        lines.read_moordyn(deck, motion={"body1": motion}, static=False)


def test_no_body_code_without_bodies(monkeypatch):
    """A deck without bodies traces none of the body code: its vector field and
    observables never call the body loads or observables."""
    scene = lines.read_moordyn(lines.case_path("pendulum.txt"), static=False)
    assert scene.model.bodies == () and scene.model.body_motions == ()

    def boom(*args, **kw):
        raise AssertionError("body code traced")

    monkeypatch.setattr(models.LineNetwork, "_body_loads", boom)
    monkeypatch.setattr(models.LineNetwork, "_body_observables", boom)
    monkeypatch.setattr(models.LineNetwork, "_frame_sets", boom)
    model = scene.model
    jax.make_jaxpr(lambda y: model.vector_field(0.0, y, scene.effects,
                                                scene.env))(scene.y0)  # fmt: skip
    obs = jax.eval_shape(lambda y: model.observables(0.0, y, scene.effects,
                                                     scene.env), scene.y0)  # fmt: skip
    assert not any(k.startswith("body_") for k in obs)
