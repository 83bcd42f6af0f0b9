"""Bending stiffness of mooring lines (MoorDyn's EI), checked against MoorDyn's
formula and its beam decks (MoorDyn 2.7.1's `beam.cpp`):

- the nodal bending forces against a plain transcription of MoorDyn's loop
  (Line.cpp: curvature 4 sin(theta/2)/l_sum, bending plane, force pairs), with
  hinged and clamped ends;
- a network without EI traces no bending, and a straight line gets exactly zero
  force with finite derivatives;
- the simply supported and cantilevered beam decks (19 segments, clamped by a
  fixed rod): static deflection within 1 % of Euler-Bernoulli, node by node within
  MoorDyn's 50 %, and equal to the exact equilibrium of MoorDyn's discrete
  equations; converging with the segment count (slow); the cantilever's first
  bending period (slow).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines
from jaxstring.lines import bending, models

from ..helpers import central_differences


G = 9.80665
P = 100.0 * G  # the beam's weight per length, N/m
EI, L = 1.0e7, 10.0


def _moordyn_bending(r, EI, qA=None, qB=None):
    """MoorDyn's bending loop (Line.cpp), node by node: forces `(N + 1, 3)` and
    curvatures; qA / qB: the clamped ends' tangents (None: hinged)."""
    N = len(r) - 1
    qs = np.diff(r, axis=0)
    ls = np.linalg.norm(qs, axis=1)
    qs = qs / ls[:, None]

    def curv(length, q1, q2):
        c = float(np.dot(q1, q2))
        if c + np.finfo(float).eps > 1:
            return 0.0
        return 4 / length * math.sqrt(0.5 * (1 - c))

    B, K = np.zeros((N + 1, 3)), np.zeros(N + 1)
    for i in range(N + 1):
        if i == 0 and qA is not None:
            K[i] = curv(ls[0], qA, qs[0])
            p = np.cross(qA, qs[0])
        elif i == N and qB is not None:
            K[i] = curv(ls[N - 1], qs[N - 1], qB)
            p = np.cross(qs[N - 1], qB)
        elif 0 < i < N:
            K[i] = curv(ls[i - 1] + ls[i], qs[i - 1], qs[i])
            p = np.cross(qs[i - 1], qs[i])
        if K[i] == 0:
            continue
        p = p / np.linalg.norm(p)
        if i > 0:
            f = np.cross(qs[i - 1], p) * K[i] * EI / ls[i - 1]
            B[i - 1] += f
            B[i] -= f
        if i < N:
            f = np.cross(qs[i], p) * K[i] * EI / ls[i]
            B[i + 1] += f
            B[i] -= f
    return B, K


def _network(r, clamp_a=None, clamp_b=None, EI=2.0e4):
    """A one-line network through the node positions r (ends fixed, or on the
    ends of fixed rods along the given tangents)."""
    N = len(r) - 1
    one = lambda v: jnp.array([float(v)])
    points, rods, ends = [], [], []
    for pos, t, side in ((r[0], clamp_a, "B"), (r[-1], clamp_b, "A")):
        if t is None:
            points.append(js.FixedEnd(jnp.asarray(pos)))
            ends.append(len(points) - 1)
        else:
            # a rod ending (side B) or starting (side A) at the line's end
            t = np.asarray(t) / np.linalg.norm(t)
            a, b = (pos - t, pos) if side == "B" else (pos, pos + t)
            rods.append(lines.Rod(a, b, 1, 0.2, 10.0))
            ends.append(lines.RodEnd(len(rods) - 1, side))
    if not points:
        points.append(js.FixedEnd(jnp.zeros(3)))
    return lines.LineNetwork(
        points=tuple(points), attach=(tuple(ends),), segments=(N,), L=one(100.0),
        d=one(0.1), w=one(10.0), EA=one(1e8), BA=one(0.0), Cd=one(0.0),
        Ca=one(0.0), CdAx=one(0.0), CaAx=one(0.0), EI=one(EI), rods=tuple(rods),
    )  # fmt: skip


def _bending_of(model, r):
    """The model's bending forces and curvatures at the line nodes r."""
    y = jnp.concatenate([r[1:-1], np.zeros_like(r[1:-1])], axis=1)
    force, curvature = _forces_and_curvatures(model, jnp.asarray(y))
    return np.asarray(force), np.asarray(curvature), model.topology


@eqx.filter_jit
def _forces_and_curvatures(model, y):
    st = model._state(0.0, y, (), js.Environment())
    return st.node_force, st.curvature


@pytest.mark.parametrize("clamped", ["none", "A", "B", "both"])
def test_bending_forces_match_moordyn(clamped):
    rng = np.random.default_rng(3)
    N = 6
    r = np.cumsum(rng.uniform(-1, 1, (N + 1, 3)) + [3.0, 0, 0], axis=0)
    qA = rng.normal(size=3) + [3, 0, 0] if clamped in ("A", "both") else None
    qB = rng.normal(size=3) + [3, 0, 0] if clamped in ("B", "both") else None
    qA = None if qA is None else qA / np.linalg.norm(qA)
    qB = None if qB is None else qB / np.linalg.norm(qB)
    EIv = 2.0e4
    model = _network(r, qA, qB, EIv)
    f, K, _ = _bending_of(model, r)
    # no axial force: the segments (16.7 m unstretched) are slack
    B, Kref = _moordyn_bending(r, EIv, qA, qB)
    scale = np.max(np.abs(B))
    np.testing.assert_allclose(f, B, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(K, Kref, rtol=1e-12, atol=1e-15)


def test_straight_line_zero_force_finite_gradient():
    """A straight line (and a line straight through a clamp) gets exactly zero
    bending force, and the force's derivative at the straight state is finite."""
    r = np.stack([np.linspace(0, 6, 7), np.zeros(7), np.zeros(7)], 1)
    model = _network(r, clamp_a=[1.0, 0, 0])
    f, K, _ = _bending_of(model, r)
    assert np.all(f == 0) and np.all(K == 0)
    qs = jnp.asarray(np.diff(r, axis=0) / 1.0)
    bend = model.topology.bending
    t_a = jnp.array([[1.0, 0, 0]])

    def force(x):
        return bending.bending_forces(
            x, jnp.ones(6), jnp.full(6, 2e4), bend, t_a, jnp.zeros((0, 3)), 7
        )[0]

    J = jax.jit(jax.jacfwd(force))(qs)
    assert np.all(np.isfinite(np.asarray(J))) and np.max(np.abs(J)) > 0


def test_no_bending_without_EI(monkeypatch):
    """A deck without EI > 0 builds a network with EI None and no rods: the
    vector field never calls the bending forces (nothing of it is traced)."""
    scene = lines.read_moordyn(lines.case_path("pendulum.txt"), static=False)
    assert scene.model.EI is None and scene.model.rods == ()

    def boom(*args, **kw):
        raise AssertionError("bending traced")

    monkeypatch.setattr(models, "bending_forces", boom)
    jax.make_jaxpr(lambda y: scene.model.vector_field(0.0, y, scene.effects,
                                                      scene.env))(scene.y0)  # fmt: skip
    assert "curvature" not in scene.observables(scene.y0)


# ---------------------------------------------------------------------------
# Beams (MoorDyn's beam.cpp)


def _simply_supported(x):
    return -P * x * (L**3 - 2 * x**2 * L + x**3) / (24 * EI)


def _cantilever(x):
    return -P * x**2 * (6 * L**2 - 4 * x * L + x**2) / (24 * EI)


def _beam(name, N=None):
    deck = lines.parse_moordyn(lines.case_path(name))
    if N is not None:
        deck.lines[0]["segments"] = N
    scene = lines.deck_scene(deck, free_points="solve")
    return np.asarray(scene.observables(scene.y0)["nodes"])


def _errors(x, exact):
    """Largest deflection error over the largest deflection, and MoorDyn's
    test measure (each node's error over its own deflection, at the nodes that
    deflect: a clamped or pinned end's exact deflection is zero, or of the order
    of rounding where its abscissa is off by an ulp)."""
    z, ze = x[:, 2] - 10.0, exact(x[:, 0])
    err = np.abs(z - ze)
    moves = np.abs(ze) > 1e-9 * np.max(np.abs(ze))
    own = err[moves] / np.abs(ze[moves])
    return np.max(err) / np.max(np.abs(ze)), np.max(own)


def test_simply_supported_beam():
    """19 segments between fixed points: largest deflection error 0.39 % of
    Euler-Bernoulli's (MoorDyn's own initial condition: 2.1 %; its test allows
    50 % per node); node 9 equals the exact equilibrium of MoorDyn's discrete
    equations (-0.012677 m)."""
    x = _beam("BeamSimplySupported.txt")
    rel, own = _errors(x, _simply_supported)
    assert rel < 0.01 and own < 0.01  # 0.0039, 0.0039
    assert own <= 0.5  # MoorDyn's test
    assert x[9, 2] - 10 == pytest.approx(-0.012677, rel=1e-4)


def test_cantilevered_beam():
    """19 segments clamped by a fixed rod: the tip deflects within 0.28 % of
    Euler-Bernoulli's (MoorDyn's own initial condition: 22 %, not converged);
    every node within MoorDyn's 50 % (node 1, next to the clamp, is the worst at
    3.6 %); the tip equals MoorDyn's exact discrete equilibrium (-0.122908 m)."""
    x = _beam("BeamCantilevered.txt")
    rel, own = _errors(x, _cantilever)
    assert rel < 0.01  # 0.0028
    assert own <= 0.5  # 0.036 (MoorDyn's test)
    assert x[-1, 2] - 10 == pytest.approx(-0.122908, rel=1e-4)
    # the clamp holds the line's end tangent along the rod (+x)
    assert x[0, 2] == 10.0 and abs(x[1, 2] - 10) < 1e-3


def _tie_beam(x, EA=1.5e9):
    """The simply supported beam with its membrane tension: both ends held, the
    sag stretches the beam, T = EA (arc length - L)/L; EI w'''' - T w'' = -p."""
    T = 1.0
    xs = np.linspace(0, L, 20001)
    for _ in range(50):
        k = math.sqrt(T / EI)
        w = lambda s: -P / (2 * T) * s * (L - s) + P * EI / T**2 * (
            1 - np.cosh(k * (s - L / 2)) / math.cosh(k * L / 2)
        )  # fmt: skip
        slope = np.gradient(w(xs), xs)
        T = EA * np.trapezoid(0.5 * slope**2, xs) / L
    return w(x)


@pytest.mark.slow
def test_beams_converge_with_segments():
    """Cantilever: the tip error falls as 1/N^2 (4.0 %, 1.0 %, 0.25 %, 0.062 % at
    N = 5, 10, 20, 40); the worst node (next to the clamp, whose curvature is
    one-sided) as 1/N. Simply supported: the deck's beam is held at both ends, so
    its sag stretches it and the membrane tension stiffens it by 0.6 %: the
    discrete beam converges to that tie-beam solution, not to Euler-Bernoulli
    (error 2.6 %, 0.36 %, 0.036 %, 0.003 % of the largest deflection at N = 5,
    10, 20, 40), while staying within 1 % of Euler-Bernoulli from N = 10 on."""
    tips, worst, tie = [], [], []
    Ns = (5, 10, 20, 40)
    for N in Ns:
        x = _beam("BeamCantilevered.txt", N)
        tips.append(abs((x[-1, 2] - 10) / _cantilever(x[-1, 0]) - 1))
        worst.append(_errors(x, _cantilever)[1])
        x = _beam("BeamSimplySupported.txt", N)
        tie.append(_errors(x, _tie_beam)[0])
        if N >= 10:
            assert _errors(x, _simply_supported)[0] < 0.01
    tips, worst, tie = map(np.asarray, (tips, worst, tie))
    order = np.log2(tips[:-1] / tips[1:])
    assert np.all(order > 1.9) and tips[-1] < 1e-3
    assert np.all(np.log2(worst[:-1] / worst[1:]) > 0.9)
    assert np.all(np.diff(tie) < 0) and tie[-1] < 1e-3


@pytest.mark.slow
def test_cantilever_first_bending_period():
    """Released from twice its static deflection, the 19-segment cantilever
    swings about its static shape with Euler-Bernoulli's first period,
    2 pi / (1.8751^2 sqrt(EI / (w L^4))) = 0.5651 s, within 1 %."""
    scene = lines.read_moordyn(lines.case_path("BeamCantilevered.txt"),
                               free_points="solve", t1=1.2)  # fmt: skip
    y0 = scene.y0.at[:, 2].set(10 + 2 * (scene.y0[:, 2] - 10))
    scene = js.Scene(scene.model, scene.effects, y0, t1=1.2, env=scene.env)
    ts = np.linspace(0.0, 1.2, 241)
    traj = js.simulate(scene, "kvaerno5", rtol=1e-5, atol=1e-5, ts=ts)
    assert traj.ok
    z = np.asarray(traj.obs["nodes"][:, -1, 2]) - 10 + 0.122908
    i = np.nonzero(np.diff(np.sign(z)))[0]
    tz = ts[i] - z[i] * (ts[i + 1] - ts[i]) / (z[i + 1] - z[i])
    T_exact = 2 * math.pi / (1.875104**2 * math.sqrt(EI / (100.0 * L**4)))
    np.testing.assert_allclose(2 * np.diff(tz), T_exact, rtol=0.01)


@pytest.mark.slow
def test_tip_gradient_in_EI_matches_central_differences():
    """The cantilever (6 segments, its EA lowered to 1e7 N so that the axial
    mode does not set the step) released straight: d(tip height at 0.05 s)/dEI
    by forward-mode autodiff through Kvaerno5 against central differences (h =
    1e-3 EI): within 1e-5 relative. A stiffer beam sags less, so the derivative
    is positive."""
    deck = lines.parse_moordyn(lines.case_path("BeamCantilevered.txt"))
    deck.lines[0]["segments"] = 6
    deck.types["beam"]["EA"] = 1e7
    scene = lines.deck_scene(deck, static=False, t1=0.05)
    config = js.SolveConfig(solver="kvaerno5", rtol=1e-10, atol=1e-10,
                            ts=jnp.array([0.05]), adjoint="forward")  # fmt: skip
    EI0 = scene.model.EI

    def tip(p):
        s = eqx.tree_at(lambda s: s.model.EI, scene, p[0] * EI0)
        return js.solve(s, config).obs["nodes"][-1, -1, 2:]

    p0 = jnp.array([1.0])
    dz = jax.jacfwd(tip)(p0)
    fd = central_differences(tip, p0, 1e-3)
    assert float(dz[0, 0]) > 0
    np.testing.assert_allclose(dz, fd, rtol=1e-5)
