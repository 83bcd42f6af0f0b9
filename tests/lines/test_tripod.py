"""MoorDyn's tripod deck (`tripod.txt`, MoorDyn's `tripod.cpp` runs it 3 s and
checks only that it runs): nine free points joined by eleven lines with bending
stiffness, among them a 0.82 m thick float of 0.21 m segments that crosses the
sea surface and chains resting on a seabed of kBot = 3e6 Pa/m.

- the submerged fraction of a thick segment across the surface (MoorDyn's
  `Line::calcSubSeg`) in closed form;
- from MoorDyn's initial node positions, the acceleration of every free node and
  point against MoorDyn's (the forces and mass matrices MoorDyn reports): within
  1e-3 relative (measured 4e-4, on a chain node resting on the seabed, whose
  contact edge jaxstring smooths over 1 mm);
- the point positions over 0.4 s against MoorDyn run at dtM = 1e-5 s, where its
  solution has converged: within 1 mm (measured 0.3 mm at 0.4 s; the
  smoothed seabed edge and the timing of the float's surface crossing). The
  deck's own dtM of
  5.5e-5 s is past RK4's stability limit for the float's bending mode once a
  float node rises out of the water (about 0.32 s: the mode's frequency goes
  from 4.4e4 to 5.4e4 rad/s, and |lambda| dtM from 2.4 to 3.0 > 2 sqrt(2));
  there MoorDyn's points jump 13 m within 0.1 s (MoorDyn's CFL counts only the
  axial waves), while dtM = 2.75e-5 s and 1e-5 s agree within 2e-6 m at 0.4 s
  (and 1e-4 m for 1.9 s).
"""

import math
import os
import shutil

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import lines
from jaxstring.lines.models import submerged_fraction
from jaxstring.testing.moordyn_start import from_moordyn_nodes, point_nodes


def test_submerged_fraction_of_a_thick_segment():
    """A segment across the surface counts the part under it of the diagonal
    from its lower end's bottom to its upper end's top (MoorDyn), r sin(phi)
    past each node, phi its angle from the vertical: (r sin(phi) - z_min) /
    (z_max - z_min + 2 r sin(phi))."""
    r = 0.41
    phi = math.radians(40.0)
    q = jnp.array([[math.sin(phi), 0.0, math.cos(phi)]] * 5)
    za = jnp.array([-0.17, -0.5, 0.2, -1e-3, 0.0])
    zb = jnp.array([0.31, -0.1, 0.6, 0.3, 0.0])
    F = np.asarray(submerged_fraction(za, zb, q, jnp.full(5, r)))
    reach = r * math.sin(phi)
    expect = [(reach + 0.17) / (0.48 + 2 * reach), 1.0, 0.0,
              (reach + 1e-3) / (0.301 + 2 * reach), 0.5]  # fmt: skip
    np.testing.assert_allclose(F, expect, rtol=1e-14)
    # a vertical segment (or a thin line): the linear fraction of its span
    qv = jnp.array([[0.0, 0.0, 1.0]])
    F = submerged_fraction(jnp.array([-0.3]), jnp.array([0.1]), qv, jnp.array([r]))
    np.testing.assert_allclose(F, [0.75], rtol=1e-14)
    # a horizontal segment whose axis lies on the surface is half wet
    qh = jnp.array([[1.0, 0.0, 0.0]])
    F = submerged_fraction(jnp.array([0.0]), jnp.array([0.0]), qh, jnp.array([r]))
    np.testing.assert_allclose(F, [0.5], rtol=1e-14)


def test_submerged_fraction_is_continuous_across_the_surface():
    """MoorDyn's fraction jumps where a node of a thick inclined segment crosses
    the surface (from 1 to 0.5 for a near-horizontal float segment): a node
    floating there has no equilibrium and an adaptive step collapses on it. Here
    it ramps over +-SURFACE_BAND: continuous, monotone in each node's height,
    within [0, 1], and MoorDyn's value once the node is out of the band."""
    from jaxstring.lines.models import SURFACE_BAND

    r, b = 0.41, SURFACE_BAND
    q = jnp.array([[0.99, 0.0, 0.1411]]) / math.hypot(0.99, 0.1411)
    reach = r * float(np.linalg.norm(q[0, :2]))
    z_lo = -0.0018  # the lower node, under the band

    def F(z_hi):
        z_hi = jnp.asarray(z_hi, jnp.float64)
        return submerged_fraction(
            jnp.full_like(z_hi, z_lo), z_hi, q, jnp.full_like(z_hi, r)
        )

    crossing = lambda z: (reach - z_lo) / (z - z_lo + 2 * reach)  # MoorDyn's, z > 0
    z = np.linspace(-3 * b, 3 * b, 6001)
    f = np.asarray(F(z))
    assert np.all((f >= 0) & (f <= 1)) and np.all(np.diff(f) <= 1e-15)
    assert np.max(np.abs(np.diff(f))) < 1e-3  # a jump of 0.5 before
    np.testing.assert_array_equal(f[z <= -b], 1.0)
    np.testing.assert_allclose(f[z >= b], crossing(z[z >= b]), rtol=1e-14)
    assert abs(crossing(0.0) - 0.5) < 0.01  # the jump MoorDyn makes at z = 0
    # the lower node leaving the water: from MoorDyn's crossing value to 0
    g = lambda zl: submerged_fraction(
        jnp.asarray(zl),
        jnp.full_like(jnp.asarray(zl), 0.3),
        q,
        jnp.full_like(jnp.asarray(zl), r),
    )
    zl = np.linspace(-3 * b, 3 * b, 6001)
    fl = np.asarray(g(zl))
    assert np.max(np.abs(np.diff(fl))) < 1e-3 and np.all(np.diff(fl) <= 1e-15)
    np.testing.assert_array_equal(fl[zl >= b], 0.0)
    np.testing.assert_allclose(
        fl[zl <= -b],
        (reach - zl[zl <= -b]) / (0.3 - zl[zl <= -b] + 2 * reach),
        rtol=1e-14,
    )


def _moordyn(tmp_path, dtM=None):
    """MoorDyn's system of the deck (copied: MoorDyn writes its log beside it),
    initialised (TmaxIC 0: no initial-condition solve)."""
    moordyn = pytest.importorskip("moordyn")
    path = os.path.join(tmp_path, "tripod.txt")
    shutil.copy(lines.case_path("tripod.txt"), path)
    system = moordyn.Create(path)
    if dtM is not None:
        moordyn.SetDt(system, dtM)
    moordyn.Init(system, [], [])
    return moordyn, system


def _scene_from(moordyn, system, t1):
    """The deck's scene started from MoorDyn's node positions (its catenary start
    draws a taut line as an elastic catenary, jaxstring's as a straight one:
    up to 4 cm apart)."""
    scene = lines.read_moordyn(lines.case_path("tripod.txt"), t1=t1, static=False)
    return from_moordyn_nodes(scene, moordyn, system)


def _point_positions(model, nodes):
    """`(..., n_points, 3)` from the `nodes` observable."""
    return nodes[..., point_nodes(model), :]


def test_tripod_accelerations_match_moordyn(tmp_path):
    """Every free node's and point's acceleration at the start, jaxstring's
    against MoorDyn's (M^-1 F of its reported force and mass matrix), within
    1e-3 relative plus 1e-6 m/s^2. The accelerations span 5e-4 to 7e3 m/s^2:
    the float's submerged fraction and the seabed's reach each changed some by
    more than 100 %."""
    moordyn, system = _moordyn(tmp_path)
    try:
        scene = _scene_from(moordyn, system, 1.0)
        # MoorDyn evaluates its forces in a step: one of 1e-12 s leaves the state
        moordyn.Step(system, [], [], 0.0, 1e-12)
        m = scene.model
        top = m.topology
        rows, slot = np.asarray(top.tri_rows), np.asarray(top.body)
        vf = eqx.filter_jit(m.vector_field)
        acc = np.asarray(vf(scene.t0, scene.y0, scene.effects, scene.env))[rows, 3:]
        md, ours = [], []
        for k in range(m.n_lines):
            line = moordyn.GetLine(system, k + 1)
            idx = m.line_nodes(k)
            for i in range(1, len(idx) - 1):
                M = np.array(moordyn.GetLineNodeM(line, i))
                md.append(np.linalg.solve(M, moordyn.GetLineNodeForce(line, i)))
                ours.append(acc[slot[idx[i]]])
        for i, p in enumerate(m.points):
            if isinstance(p, lines.FreePoint):
                pt = moordyn.GetPoint(system, i + 1)
                M = np.array(moordyn.GetPointM(pt))
                md.append(np.linalg.solve(M, moordyn.GetPointForce(pt)))
                k = next(k for k, e in enumerate(m.attach) if i in e)
                n = m.line_nodes(k)[0 if m.attach[k][0] == i else -1]
                ours.append(acc[slot[n]])
    finally:
        moordyn.Close(system)
    md, ours = np.array(md), np.array(ours)
    size = np.linalg.norm(md, axis=1)
    assert size.min() < 1e-3 and size.max() > 5e3
    err = np.linalg.norm(ours - md, axis=1)
    assert np.all(err <= 1e-3 * size + 1e-6), np.max(err / size)


@pytest.mark.slow
def test_tripod_points_follow_converged_moordyn(tmp_path):
    """The nine free points every 0.1 s for 0.4 s (through the float's node
    rising out of the water at about 0.32 s), jaxstring (Tsit5, rtol = atol =
    1e-7) against MoorDyn at dtM = 1e-5 s: within 1 mm (measured 0.3 mm), while
    the points move up to 0.46 m."""
    moordyn, system = _moordyn(tmp_path, dtM=1e-5)
    try:
        scene = _scene_from(moordyn, system, 0.4)
        points = [moordyn.GetPoint(system, i + 1) for i in range(12)]
        ref = [[moordyn.GetPointPos(p) for p in points]]
        for k in range(4):
            moordyn.Step(system, [], [], 0.1 * k, 0.1)
            ref.append([moordyn.GetPointPos(p) for p in points])
    finally:
        moordyn.Close(system)
    ref = np.array(ref)
    ts = np.linspace(0.0, 0.4, 5)
    traj = js.simulate(scene, "tsit5", rtol=1e-7, atol=1e-7, ts=ts, max_steps=100_000)
    assert traj.ok
    P = _point_positions(scene.model, np.asarray(traj.obs["nodes"]))
    moved = np.max(np.linalg.norm(ref - ref[0], axis=-1))
    assert moved > 0.3
    np.testing.assert_allclose(P, ref, atol=1e-3)
