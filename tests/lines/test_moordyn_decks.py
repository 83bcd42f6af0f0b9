"""Mooring-line networks and MoorDyn decks, checked against MoorDyn's own validation
cases (decks and reference data of MoorDyn 2.7.1, shipped in jaxstring/lines/cases):

- deck parsing: the numbers of the decks, and a ValueError naming the line and
  column for a malformed row and for an unsupported section;
- the pendulum (MoorDyn's pendulum test): the rigid pendulum's period within
  2.5 % and its amplitude within 1 %;
- lifting (MoorDyn's lifting test): the unstretched length shrinks at 1 m/s for
  10 s and the hanging point follows it;
- WD0050 chain: static fairlead and anchor tensions against the reference
  code's values (MoorDyn's test allows 10 %; here 2 %);
- gradients of the static tensions (implicit-function derivative of the
  equilibrium) and of a dynamic tension against central differences;
- the axial drag's two reference areas (MoorDyn's pi d, DNV's and OrcaFlex's d)
  against Morison's formula; WD0200's dynamic fairlead tension against the
  reference series (slow).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines

from ..helpers import central_differences


G = 9.80665  # MoorDyn's gravity, the decks' default


@pytest.fixture(scope="module")
def wd0050(tmp_path_factory):
    # its static state solved through a saved program, as a process with the
    # compilation cache on (the default) does
    from jaxstring import _programs

    folder = tmp_path_factory.mktemp("programs")
    _programs.set_program_folder(str(folder))
    try:
        scene = lines.read_moordyn(lines.case_path("WD0050_Chain.txt"))
    finally:
        _programs.set_program_folder(None)
    assert list(folder.glob("*.program"))
    return scene


# ---------------------------------------------------------------------------
# Decks


def test_parse_chain_deck():
    deck = lines.parse_moordyn(lines.case_path("WD0050_Chain.txt"))
    chain = deck.types["chain"]
    assert chain == {"d": 0.252, "w": 390.0, "EA": 1.674e9, "BA": -1.0, "EI": 0.0,
                     "Cd": 1.37, "Ca": 1.0, "CdAx": 0.64, "CaAx": 0.0,
                     "Cl": 0.0}  # fmt: skip
    assert [p["kind"] for p in deck.points] == ["fixed", "coupled"]
    assert deck.points[0]["position"] == [400.0, 0.0, -50.0]
    assert deck.lines == [{"id": 1, "type": "chain", "a": 1, "b": 2, "L": 410.0,
                           "segments": 41}]  # fmt: skip
    o = deck.options
    assert (o["depth"], o["kBot"], o["cBot"], o["friction"]) == (50, 1e5, 1e4, 0.5)
    assert (o["g"], o["rho"]) == (G, 1025.0)  # MoorDyn's default g
    assert deck.numerics["cfl"] == "0.1"
    # three lines and six points of the OC3-Hywind deck
    deck = lines.parse_moordyn(lines.case_path("lines.txt"))
    assert len(deck.lines) == 3 and len(deck.points) == 6
    assert deck.numerics["dtM"] == "0.002"


def _write(tmp_path, text):
    path = tmp_path / "deck.txt"
    path.write_text(text)
    return str(path)


def _deck_lines():
    with open(lines.case_path("pendulum.txt")) as f:
        return f.read().splitlines()


def test_malformed_row_names_line_and_column(tmp_path):
    rows = _deck_lines()
    i = next(k for k, r in enumerate(rows) if r.startswith("main"))
    rows[i] = rows[i].replace("1.0E9", "1.0E9x")
    col = rows[i].index("1.0E9x") + 1
    with pytest.raises(ValueError, match=rf"line {i + 1}, column {col}: .*EA"):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows)))
    # a line attached to a point that does not exist
    rows = _deck_lines()
    j = next(k for k, r in enumerate(rows) if r.startswith("1     main"))
    rows[j] = "1 main 1 7 100.5 20 -"
    with pytest.raises(ValueError, match=rf"line {j + 1}, column 10: point 7"):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows)))


def test_unsupported_section_and_option(tmp_path):
    rows = _deck_lines()
    k = next(i for i, r in enumerate(rows) if "LINES" in r)
    failure = [
        "---------------------- FAILURE ----------------------------",
        "ID Point Line FailTen",
    ]
    with pytest.raises(ValueError, match=rf"line {k + 1}, column 1: section 'FAILURE'"):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows[:k] + failure + rows[k:])))
    rows = _deck_lines()
    k = next(i for i, r in enumerate(rows) if "WtrDpth" in r)
    rows.insert(k, "1             WaterKin      wave kinematics")
    with pytest.raises(ValueError, match=rf"line {k + 1}, column 1: option WaterKin"):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows)))


def test_bad_point_type(tmp_path):
    rows = _deck_lines()
    k = next(i for i, r in enumerate(rows) if r.startswith("2     Free"))
    rows[k] = rows[k].replace("Free", "Body1")
    with pytest.raises(
        ValueError, match=rf"line {k + 1}, column 7: .*body 1 is not in BODIES"
    ):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows)))
    rows[k] = rows[k].replace("Body1", "Floating")
    with pytest.raises(ValueError, match=rf"line {k + 1}, column 7: point type"):
        lines.parse_moordyn(_write(tmp_path, "\n".join(rows)))


# ---------------------------------------------------------------------------
# Loads


def _one_node(velocity, tangent, d=0.25, length=10.0):
    z1 = jnp.zeros(1)
    z0 = jnp.zeros((0, 3))
    return js.chain.ChainKinematics(
        positions=jnp.array([[0.0, 0.0, -10.0]]),
        velocities=jnp.asarray([velocity], jnp.float64),
        tangents=jnp.asarray([tangent], jnp.float64),
        mass=z1, volume=z1, length=z1 + length, wetted_length=z1 + length,
        diameter=z1 + d, Cd=z1 + 1.37, CdAx=z1 + 0.64,
        point_positions=z0, point_velocities=z0, point_mass=jnp.zeros(0),
        point_volume=jnp.zeros(0), point_CdA=jnp.zeros(0),
    )  # fmt: skip


def test_axial_drag_area():
    """Morison drag on a node moving at 2 m/s along its axis: 1/2 rho CdAx A |v| v
    with A = pi d l (MoorDyn, default) or d l (DNV-OS-E301, OrcaFlex's chain);
    the normal drag 1/2 rho Cd d l |v| v is the same in both."""
    env = js.Environment()
    rho, d, l = float(env.rho_water), 0.25, 10.0
    axial = _one_node([2.0, 0.0, 0.0], [1.0, 0.0, 0.0])
    normal = _one_node([0.0, 0.0, 2.0], [1.0, 0.0, 0.0])
    for area, A in (("surface", math.pi * d * l), ("diameter", d * l)):
        drag = lines.Drag(axial_area=area)
        f = np.asarray(drag.forces(0.0, axial, env).nodes[0])
        np.testing.assert_allclose(f, [-0.5 * rho * 0.64 * A * 4.0, 0, 0], rtol=1e-12)
        f = np.asarray(drag.forces(0.0, normal, env).nodes[0])
        np.testing.assert_allclose(f, [0, 0, -0.5 * rho * 1.37 * d * l * 4.0])
    with pytest.raises(ValueError, match="axial_area"):
        lines.Drag(axial_area="wetted")
    with pytest.raises(ValueError, match="axial_drag"):
        lines.read_moordyn(lines.case_path("WD0050_Chain.txt"), axial_drag="pi")
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['t2'\]"):
        lines.read_moordyn(lines.case_path("WD0050_Chain.txt"), t2=5.0)
    with pytest.raises(ValueError, match=r"unknown option\(s\) \['tolerance'\]"):
        lines.coupled_stiffness(None, tolerance=1e-8)


def test_ramp_in():
    """The ramp starts from rest at the table's first time and is the table
    from `duration` on."""
    t = np.arange(-10.0, 5.0 + 1e-9, 0.1)
    off = np.stack([0 * t, 0 * t, 2 * np.sin(0.2 * np.pi * t)], 1)
    r = lines.ramp_in(t, off, 10.0)
    np.testing.assert_array_equal(r[t >= 0.0], off[t >= 0.0])
    assert r[0, 2] == 0.0 and abs(r[1, 2]) < 1e-3 * abs(off[1, 2])
    with pytest.raises(ValueError, match="duration"):
        lines.ramp_in(t, off, 0.0)


# ---------------------------------------------------------------------------
# Static tensions


def test_wd0050_static_tensions(wd0050):
    """Reference code (MoorDyn's test): fairlead 991.6 kN, anchor 826.2 kN."""
    ta, tb = lines.static_tensions(wd0050)[1]
    assert abs(tb / 991.6e3 - 1) < 0.02
    assert abs(ta / 826.2e3 - 1) < 0.02
    obs = wd0050.observables(wd0050.y0)
    fa, fb = np.asarray(obs["end_force_a"][0]), np.asarray(obs["end_force_b"][0])
    # seabed friction is zero at rest: the two ends' horizontal pulls balance
    assert abs(fa[0] + fb[0]) < 1e-6 * abs(fb[0])
    nodes = np.asarray(obs["nodes"])
    assert np.min(nodes[:, 2]) > -50.2  # seabed penetration ~ w/(kBot d) = 0.13 m
    # the static solve's own end tensions are those of the state it returned
    fresh = lines.moordyn._rest_observables(wd0050)
    np.testing.assert_allclose((ta, tb), (fresh["tension_a"][0], fresh["tension_b"][0]),
                               rtol=1e-12)  # fmt: skip
    # a scene changed after the read gets its own tensions: twice the axial
    # stiffness at the same shape, about twice the segment tension (the end
    # nodes' weight, 2 % of it, unchanged)
    stiff = eqx.tree_at(lambda s: s.model.EA, wd0050, wd0050.model.EA * 2)
    ta2, tb2 = lines.static_tensions(stiff)[1]
    assert abs(ta2 / ta - 2) < 0.05 and abs(tb2 / tb - 2) < 0.05


def test_static_gradients(wd0050):
    """d(static fairlead and anchor tension)/d(EA, kBot, w) through the
    equilibrium's implicit-function derivative vs central differences."""
    scene = wd0050

    def tensions(p):
        m = eqx.tree_at(lambda m: (m.EA, m.w), scene.model, (p[0:1], p[2:3]))
        bed = eqx.tree_at(lambda e: e.kBot, scene.effects[3], p[1])
        eff = scene.effects[:3] + (bed,)
        y, _ = lines.equilibrium(m, eff, scene.env, scene.t0, y0=scene.y0)
        s = eqx.tree_at(lambda s: (s.model, s.effects, s.y0), scene, (m, eff, y))
        t = lines.moordyn._rest_observables(s)
        return jnp.stack([t["tension_a"][0], t["tension_b"][0]])

    p0 = jnp.array([1.674e9, 1.0e5, 390.0])
    J = jax.jacrev(tensions)(p0)
    # steps of 1e-3: the solve stops at residuals of ~1e-3 N
    np.testing.assert_allclose(J, central_differences(tensions, p0, 1e-3), rtol=1e-4)
    # heavier chain: higher tensions (about L_suspended * g per kg/m)
    assert J[1, 2] > 100 * G


@pytest.mark.slow
def test_fairlead_tension_gradient_in_EA_matches_central_differences():
    """MoorDyn's pendulum deck (4 segments, EA 1e7 N) released from its static
    state: d(tension at the fixed end at 1 s)/dEA by forward-mode autodiff
    through Kvaerno5 against central differences (h = 1e-3 EA): within 1e-5
    relative (measured 2e-6)."""
    deck = lines.parse_moordyn(lines.case_path("pendulum.txt"))
    deck.lines[0]["segments"] = 4
    deck.types["main"]["EA"] = 1e7
    scene = lines.deck_scene(deck, t1=1.0)
    config = js.SolveConfig(solver="kvaerno5", rtol=1e-10, atol=1e-10,
                            ts=jnp.array([1.0]), adjoint="forward")  # fmt: skip
    EA0 = scene.model.EA

    def tension(p):
        s = eqx.tree_at(lambda s: s.model.EA, scene, p[0] * EA0)
        return js.solve(s, config).obs["tension_a"][-1]

    p0 = jnp.array([1.0])
    fd = central_differences(tension, p0, 1e-3)
    np.testing.assert_allclose(jax.jacfwd(tension)(p0), fd, rtol=1e-5)


# ---------------------------------------------------------------------------
# Dynamics


def _peaks(ts, x):
    """Times and values of the local extrema of x (parabolic refinement)."""
    out = []
    for i in range(1, len(x) - 1):
        if (x[i] - x[i - 1]) * (x[i + 1] - x[i]) < 0:
            a, b, c = x[i - 1], x[i], x[i + 1]
            den = a - 2 * b + c
            d = 0.5 * (a - c) / den
            h = ts[1] - ts[0]
            out.append((ts[i] + d * h, b - 0.25 * (a - c) * d))
    return np.array(out)


@pytest.mark.slow
def test_pendulum_period_and_amplitude():
    """MoorDyn's pendulum test: the 1e5 kg point on a 100.5 m neutrally buoyant
    line, released at rest from x = 10 m, swings with the rigid pendulum's
    period 2 pi sqrt(l0/g) (within 2.5 %) and keeps its amplitude (within 1 %)."""
    scene = lines.read_moordyn(lines.case_path("pendulum.txt"))
    x0 = float(scene.model.points[1].position[0])
    l0 = math.hypot(10.0, 100.0)
    T = 2 * math.pi * math.sqrt(l0 / G)
    scene = eqx.tree_at(lambda s: s.t1, scene, jnp.asarray(1.1 * T))
    ts = np.linspace(0.0, 1.1 * T, 441)
    traj = js.simulate(scene, "kvaerno5", rtol=1e-4, atol=1e-4, ts=ts)
    assert traj.ok
    x = np.asarray(traj.positions[:, -1, 0])
    assert x[0] == pytest.approx(x0)
    pk = _peaks(ts, x)
    pk = pk[np.abs(pk[:, 1]) > 0.5 * x0]  # the swings, not the axial ripple
    assert len(pk) == 2
    np.testing.assert_allclose(pk[:, 0], [0.5 * T, T], atol=0.025 * T)
    np.testing.assert_allclose(np.abs(pk[:, 1]), x0, rtol=0.01)
    # Half a period between the zero crossings: the rigid pendulum's, lengthened
    # by the finite amplitude (theta0^2/16), the line's inertia (a weightless rod
    # of a third of its mass at the bob's radius) and its stretch under the
    # bob's weight (l0 M g/EA), to 0.5 %.
    i = np.nonzero(np.diff(np.sign(x)))[0]
    tz = ts[i] - x[i] * (ts[i + 1] - ts[i]) / (x[i + 1] - x[i])
    assert len(tz) == 2
    m = scene.model
    M, m_line = 1e5, float(m.w[0] * m.L[0])
    l_eff = l0 * (1 + m_line / (3 * M)) + l0 * M * G / float(m.EA[0])
    T_exact = 2 * math.pi * math.sqrt(l_eff / G) * (1 + (x0 / l0) ** 2 / 16)
    assert 2 * (tz[1] - tz[0]) == pytest.approx(T_exact, rel=0.005)


@pytest.mark.slow
def test_lifting_follows_the_length():
    """MoorDyn's lifting test: the line's unstretched length shrinks at 1 m/s for
    10 s; the 1e3 kg point hangs at z = -L(t) within 0.5 m from t = 1 s on (it
    starts 0.5 m below its slack line), and L(t) is exactly L0 - t."""
    scene = lines.read_moordyn(lines.case_path("lifting.txt"), t1=10.0)
    L0 = float(scene.model.L[0])
    sched = js.PiecewiseLinear(jnp.array([0.0, 10.0]), jnp.array([L0, L0 - 10.0]))
    scene = eqx.tree_at(
        lambda s: s.model.lengths, scene, (sched,), is_leaf=lambda x: x is None
    )
    ts = np.linspace(0.0, 10.0, 101)
    traj = js.simulate(scene, "kvaerno5", rtol=1e-4, atol=1e-4, ts=ts)
    assert traj.ok
    L = np.asarray(traj.lengths[:, 0])
    np.testing.assert_allclose(L, L0 - ts, atol=1e-9)
    z = np.asarray(traj.positions[:, -1, 2])
    late = ts >= 1.0
    assert np.max(np.abs(z + L)[late]) < 0.5
    # at the end it hangs still on a line stretched by its weight: 1e3 g L/EA
    assert abs(z[-1] + L[-1]) < 0.05


@pytest.mark.slow
def test_wd0050_dynamic_tension_gradient():
    """d(fairlead tension at t = -9 s)/d(Cd, EA, kBot) of the WD0050 chain
    heaved by the ZZP1_A1 motion vs central differences, from the static state,
    on a fixed-step trapezoidal solve (both differentiate the same discrete map;
    forward mode through the stage Newton iterations)."""
    scene = lines.read_moordyn(
        lines.case_path("WD0050_Chain.txt"),
        motion=lines.case_path("QuasiStatic/ZZP1_A1.txt"),
        t1=-9.0,
    )
    ts = jnp.array([-10.0, -9.0])

    def tension(p):
        m = eqx.tree_at(lambda m: (m.Cd, m.EA), scene.model, (p[0:1], p[1:2]))
        bed = eqx.tree_at(lambda e: e.kBot, scene.effects[3], p[2])
        s = eqx.tree_at(
            lambda s: (s.model, s.effects), scene, (m, scene.effects[:3] + (bed,))
        )
        tr = js.simulate(
            s, "trapezoid", dt0=0.005, ts=ts, rtol=1e-10, atol=1e-10, adjoint="forward"
        )
        return tr.obs["tension_b"][-1, 0]

    p0 = jnp.array([1.37, 1.674e9, 1e5])
    g = jax.jacfwd(tension)(p0)
    # Steps of 1e-4 of each value: in kBot (seabed contact) steps of 1e-3 are off by
    # truncation (4.5e-4 relative) and steps of 1e-5 by the solves' rounding
    # (1.5e-5); at 1e-4 all three derivatives agree to 4.2e-6.
    np.testing.assert_allclose(g, central_differences(tension, p0, 1e-4), rtol=1e-5)


@pytest.mark.slow
def test_wd0200_dynamic_tension_vs_reference():
    """WD0200 heaved by ZZP1_A1 (ramped in over its t < 0 part), with the reference
    code's axial-drag area (CdAx on d): the dynamic fairlead tension T - T_static
    from t = 0 on within 8 % of the reference series' largest dynamic value
    (MoorDyn's test allows 15 % of twice that)."""
    table = np.loadtxt(lines.case_path("QuasiStatic/ZZP1_A1.txt"))
    off = lines.ramp_in(table[:, 0], table[:, 1:4], 10.0)
    scene = lines.read_moordyn(
        lines.case_path("WD0200_Chain.txt"),
        motion=(table[:, 0], off),
        axial_drag="diameter",
    )
    ref = np.loadtxt(lines.case_path("QuasiStatic/WD0200_Chain_ZZP1_A1.txt"))
    traj = js.simulate(scene, "kvaerno5", rtol=1e-5, atol=1e-5, ts=table[:, 0])
    assert traj.ok
    T = np.asarray(traj.obs["tension_b"][:, 0])
    static = lines.static_tensions(scene)[1][1]
    dT = T[table[:, 0] >= -1e-9] - static
    dT_ref = 1e3 * ref[:, 3] - 2065.4e3
    assert np.max(np.abs(dT - dT_ref)) < 0.08 * np.max(np.abs(dT_ref))
