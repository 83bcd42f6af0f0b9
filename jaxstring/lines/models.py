"""A network of mooring lines: lumped masses between points (MoorDyn's v2 model).

Lines join points. Each line of unstretched length L(t) is cut into N equal segments
(N + 1 nodes, the end nodes sitting on the line's points); node i stands for half of
each adjacent segment. A point is held (`FixedEnd`), moved on a prescribed path
(`PrescribedEnd`: a table; `MotionEnd`: a JAX function of time), or free
(`FreePoint`: mass, volume, CdA, Ca); the end nodes of every line attached to a free
point move with it and add their mass and loads to it.

Per line: diameter d, mass per length w, axial stiffness EA, internal damping BA
(a negative value -zeta is MoorDyn's damping ratio: BA = zeta (L/N) sqrt(EA w)), and
the hydrodynamic coefficients Cd, Ca, CdAx, CaAx. Segment s between nodes i and i+1
of stretched length l_s and unstretched length l = L/N carries

    T_s = EA max(l_s - l, 0)/l + BA (dl_s/dt - (l_s/l) dl/dt)/l

along its axis (a cable cannot push; the damping acts on the rate of the strain,
which includes the change of the unstretched length when a line is hauled in or paid
out). Node i has mass m_i = w l_i and the added-mass matrix
rho V_i (Ca (I - q q^T) + CaAx q q^T) about its axis q_i (V_i the submerged volume);
the loads (weight and buoyancy, Morison drag relative to the current, seabed
contact) are effects (`jaxstring.lines.effects`).

State: node-major `(n, 6)`, row = (position, velocity) of one free body: the interior
nodes of each line in order and each free point next to the first line that reaches
it, so that the Jacobian is block-banded with the bandwidth its `structure` declares
(1 for a chain of lines and points), and the implicit solvers' Newton steps cost
O(nodes). Rigid objects with degrees of freedom (bodies, rods) have rows of their own
(translation, and rotation as a quaternion and the angular velocity); where the
lines meet on them they come first, as the Jacobian's border, and the lines' nodes
form a band behind them (`_topology`).
"""

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _programs
from .._arrays import (
    FloatScalar,
    add_rows,
    dot as _dot,
    f64,
    host_op,
    param as _param,
    take_rows,
)
from .._blas import single_blas_thread
from .._environment import Environment
from .._geometry import safe_norm
from .._jit import cpu_jit
from .._model import AbstractModel, SolverStructure
from .._programs import eager_jit
from .._validate import (
    check_choice,
    check_finite,
    check_int,
    check_nonnegative,
    check_positive,
    check_shape,
    check_shape_finite,
)
from ..chain import (
    AbstractChainLoad,
    AbstractEnd,
    Buoyancy,
    ChainKinematics,
    Drag,
    Gravity,
    PiecewiseLinear,
    links,
    unit,
)
from .bending import bending_forces
from .bodies import (
    Body,
    euler_angles,
    matrix_to_quat,
    quat_to_matrix,
    rotation_matrix,
)
from .effects import Seabed
from .rigid import (
    Frame,
    PointSet,
    RigidMotion,
    Rotational,
    group_accelerations,
    quat_rate,
)
from .rods import Rod, RodEnd, rod_loads


SURFACE_BAND = 1e-3
"""Half-width of the band about the still-water surface, m, over which
`submerged_fraction` blends MoorDyn's fully wet or dry value into its value for a
segment across the surface (as the seabed's contact edge is smoothed over 1 mm)."""


def _smooth_step(x):
    """0 for x <= -1, 1 for x >= 1, C1 between (3 w^2 - 2 w^3), and
    `_smooth_step(-x) = 1 - _smooth_step(x)`."""
    w = jnp.clip(0.5 * (x + 1.0), 0.0, 1.0)
    return w * w * (3.0 - 2.0 * w)


def submerged_fraction(z_a, z_b, qs, radius):
    """Submerged fraction of each segment under the still-water surface z = 0
    (MoorDyn's `Line::calcSubSeg`), `(S,)`: 1 with both nodes below it, 0 with
    both above, and for a segment across it the part below the surface of the
    diagonal from the lower end's bottom to the upper end's top,

        F = (r sin(phi) - z_min) / (z_max - z_min + 2 r sin(phi)),

    with phi the segment's angle from the vertical and r its radius: a
    horizontal segment of diameter d whose axis lies on the surface is half
    submerged. MoorDyn's F jumps (by up to r sin(phi) / (z_max + 2 r sin(phi)))
    when a node of a thick, inclined segment crosses the surface; a float node
    whose buoyancy jumps there has no equilibrium, and an adaptive solver's step
    collapses on it (MoorDyn's fixed step chatters across it). Here the jump is
    a C1 ramp over `SURFACE_BAND` either side of the surface,

        F = F_x + s(-z_max / b) (1 - F_x) - s(z_min / b) F_x,

    F_x the formula above (clipped to [0, 1]) and s a smooth step from 0 at -1
    to 1 at +1: MoorDyn's value wherever neither node lies within b of the
    surface.

    **Arguments:** the node heights `z_a`, `z_b` `(S,)`, m; the unit segment
    directions `qs` `(S, 3)`; the segment radii `radius` `(S,)`, m.
    """
    zmin, zmax = jnp.minimum(z_a, z_b), jnp.maximum(z_a, z_b)
    # r sin(phi): the radius' vertical reach at the segment's ends
    reach = radius * safe_norm(qs[:, :2])
    den = zmax - zmin + 2.0 * reach
    # a segment lying flat on the surface (zero span and no radius): half, as
    # MoorDyn's
    frac = jnp.where(den > 0, (reach - zmin) / jnp.where(den > 0, den, 1.0), 0.5)
    frac = jnp.clip(frac, 0.0, 1.0)
    below = _smooth_step(-zmax / SURFACE_BAND)  # 1: the upper node under the band
    above = _smooth_step(zmin / SURFACE_BAND)  # 1: the lower node over it
    return frac + below * (1.0 - frac) - above * frac


def _none_or_f64(x):
    return None if x is None else f64(x)


class _AbstractPoint(eqx.Module):
    """A point with its own mass, volume and drag (`FreePoint`, `BodyPoint`): the
    checks they share."""

    position: eqx.AbstractVar[Float[Array, "3"]]
    mass: eqx.AbstractVar[FloatScalar]
    volume: eqx.AbstractVar[FloatScalar]
    CdA: eqx.AbstractVar[FloatScalar]
    Ca: eqx.AbstractVar[FloatScalar]

    def __check_init__(self):
        check_shape_finite("position", self.position, (3,), "m")
        for name, u in (("mass", "kg"), ("volume", "m^3"), ("CdA", "m^2")):
            check_shape(name, getattr(self, name), (), u)
            check_nonnegative(name, getattr(self, name), u)
        check_nonnegative("Ca", self.Ca)


class FreePoint(_AbstractPoint):
    """A free point (a clump weight, a buoy, a pendulum's bob).

    **Arguments:** `position` (its initial position, `(3,)`, m), `mass` (kg),
    `volume` (m^3), `CdA` (drag coefficient times area, m^2), `Ca` (added-mass
    coefficient on rho V), all >= 0.
    """

    position: Float[Array, "3"] = _param()
    mass: FloatScalar = _param(default=0.0)
    volume: FloatScalar = _param(default=0.0)
    CdA: FloatScalar = _param(default=0.0)
    Ca: FloatScalar = _param(default=0.0)


class BodyPoint(_AbstractPoint):
    """A point fixed on a body (MoorDyn's `Body<n>` point): it moves with the
    body, and its own loads and the lines on it load the body.

    **Arguments:** `body` (index in `LineNetwork.bodies`, structure), `position`
    (in the body's frame, relative to its reference point, `(3,)`, m), `mass`
    (kg), `volume` (m^3), `CdA` (m^2), `Ca` (added mass on rho V), all >= 0.
    """

    body: int = eqx.field(static=True)
    position: Float[Array, "3"] = _param()
    mass: FloatScalar = _param(default=0.0)
    volume: FloatScalar = _param(default=0.0)
    CdA: FloatScalar = _param(default=0.0)
    Ca: FloatScalar = _param(default=0.0)

    def __check_init__(self):
        # runs before `_AbstractPoint`'s checks (equinox: in method resolution order)
        if (
            isinstance(self.body, bool)
            or not isinstance(self.body, int)
            or (self.body < 0)
        ):
            raise ValueError(f"`body` must be an integer >= 0; got {self.body!r}.")


_LINE_PARAMS = ("L", "d", "w", "EA", "BA", "Cd", "Ca", "CdAx", "CaAx")


class _Bending(eqx.Module):
    """Static index arrays of the bending joints (see `bending.bending_forces`)."""

    inner_node: np.ndarray  # interior line node
    inner_prev: np.ndarray  # its segment on the A side
    inner_next: np.ndarray  # its segment on the B side
    clamp_a_node: np.ndarray  # end-A node of a line clamped to a rod end
    clamp_a_seg: np.ndarray  # its end segment
    clamp_a_rod: np.ndarray  # the rod
    clamp_a_sign: np.ndarray  # +1: the rod's axis points into the line
    clamp_b_node: np.ndarray
    clamp_b_seg: np.ndarray
    clamp_b_rod: np.ndarray
    clamp_b_sign: np.ndarray  # +1: the rod's axis points out of the line


class _Frames(eqx.Module):
    """Static description of the rigid frames: frame 0 is the earth, then one per
    body, then one per rod that is not fixed (a fixed rod moves with the earth's
    or its body's frame)."""

    owner: tuple  # per frame: ("earth", None) | ("body", b) | ("rod", r)
    trans: tuple  # per frame: "fixed" | "state" | "pin" | "motion"
    rot: tuple  # per frame: "fixed" | "state" | "motion"
    parent: tuple  # per frame: the frame its origin is pinned to, or None
    trans_row: tuple  # per frame: its state row (position, velocity) or None
    rot_rows: tuple  # per frame: its two state rows (quaternion, omega) or None
    groups: tuple  # per group: its frames, the root first
    dofs: tuple  # per group, per frame: (translation slice, rotation slice)
    rod_frame: tuple  # per rod: the frame it moves with

    def has_dof(self, f) -> bool:
        return self.trans[f] == "state" or self.rot[f] == "state"


class _Topology(eqx.Module):
    """Static index arrays of a network (NumPy, built at trace time).

    Every line node sits on a "body" (a slot): a three-degree-of-freedom state
    row (interior nodes and free points, in `tri_rows` order), a held point, or a
    point of a rigid frame (rod ends, points on bodies), in that order."""

    n_state: int
    tri_rows: np.ndarray  # slot j < n_tri -> its state row
    body: np.ndarray  # line node -> slot
    node_line: np.ndarray  # line node -> line
    prev: np.ndarray  # line node -> previous line node (itself at end A)
    next: np.ndarray  # line node -> next line node (itself at end B)
    seg_lo: np.ndarray  # segment -> its node at the A side
    seg_line: np.ndarray
    end_a: np.ndarray  # line -> its line node at end A
    end_b: np.ndarray
    free_rows: np.ndarray  # free point (in `free` order) -> slot
    free: tuple  # indices of the free points in `points`
    held: tuple  # indices of the held points in `points`
    on_body: tuple  # indices of the points on bodies in `points`
    point_body: np.ndarray  # point -> slot
    rod_body: np.ndarray  # (rod, end A/B) -> slot, (R, 2)
    slot_frame: np.ndarray  # rigid slot (from n_tri + H) -> frame
    bending: _Bending
    frames: _Frames
    group_rows: tuple  # per group: its state rows
    width: int  # node bandwidth of the rows after the border
    border: int  # leading rows (the rigid groups') coupled to every row, or 0
    border_coupled: tuple  # the rows after the border that the border's rows read
    border_columns: tuple  # the border's entries in use (flat, row-major)

    @property
    def n_tri(self) -> int:
        return self.tri_rows.shape[0]

    @property
    def n_bodies(self) -> int:
        return self.n_tri + len(self.held) + self.slot_frame.shape[0]

    @property
    def rigid_start(self) -> int:
        return self.n_tri + len(self.held)


def _frames_of(rods, bodies):
    """Frames (without rows) of the bodies and rods: see `_Frames`."""
    owner, trans, rot, parent = [("earth", None)], ["fixed"], ["fixed"], [None]
    for b, body in enumerate(bodies):
        owner.append(("body", b))
        trans.append({"fixed": "fixed", "free": "state", "coupled": "motion",
                      "pinned": "motion"}[body.kind])  # fmt: skip
        rot.append({"fixed": "fixed", "free": "state", "coupled": "motion",
                    "pinned": "state"}[body.kind])  # fmt: skip
        parent.append(None)
    rod_frame = []
    for r, rod in enumerate(rods):
        home = 0 if rod.body is None else 1 + rod.body
        if rod.kind == "fixed":
            rod_frame.append(home)
            continue
        rod_frame.append(len(owner))
        owner.append(("rod", r))
        trans.append({"pinned": "pin", "free": "state", "coupled": "motion",
                      "coupled_pinned": "motion"}[rod.kind])  # fmt: skip
        rot.append("motion" if rod.kind == "coupled" else "state")
        parent.append(home if rod.kind == "pinned" else None)
    return owner, trans, rot, parent, rod_frame


def _cuthill_mckee(vertices, adj):
    """The vertices in Cuthill-McKee order, component by component: breadth
    first from a pseudo-peripheral vertex, neighbours by increasing degree."""
    index = {v: i for i, v in enumerate(vertices)}

    def bfs(start, seen):
        order, levels = [start], {start: 0}
        seen.add(start)
        k = 0
        while k < len(order):
            u = order[k]
            k += 1
            for v in sorted(set(adj[u]) - seen, key=lambda v: (len(adj[v]),
                            index[v])):  # fmt: skip
                seen.add(v)
                levels[v] = levels[u] + 1
                order.append(v)
        return order, levels

    out, done = [], set()
    for v0 in vertices:
        if v0 in done:
            continue
        # a pseudo-peripheral start: the farthest vertex of a breadth-first
        # search, twice
        start = v0
        for _ in range(2):
            _, levels = bfs(start, set(done))
            far = max(levels.values())
            start = min((v for v, lv in levels.items() if lv == far),
                        key=lambda v: (len(adj[v]), index[v]))  # fmt: skip
        order, _ = bfs(start, done)
        out += order
    return out


def _band_width(rows_of, attach, segments, obj, bending, border=0):
    """The node bandwidth of the state rows after the first `border`: rows that
    one segment joins (two segments, the bending joints, with `bending`), and the
    rows of one rigid group."""
    rows = lambda v: [r for r in _vertex_rows(rows_of, v) if r >= border]
    width = 1
    for chain in _chains(attach, segments, obj):
        for reach in (2, 3) if bending else (2,):
            for i in range(len(chain) - reach + 1):
                rr = [r for v in chain[i : i + reach] for r in rows(v)]
                if rr:
                    width = max(width, max(rr) - min(rr))
    for v in rows_of:
        rr = rows(v)
        if rr:
            width = max(width, max(rr) - min(rr))
    return width


def _border_coupled(rows_of, attach, segments, obj, bending, border):
    """The rows after the first `border` (the rigid groups') that the border's
    rows depend on: those one segment (two, with `bending`) away from a rigid
    group along a line."""
    reach = 3 if bending else 2
    out = set()
    for chain in _chains(attach, segments, obj):
        for i in range(len(chain)):
            window = chain[max(0, i - reach + 1) : i + reach]
            if any(v is not None and v[0] == "g" for v in window):
                out.update(r for r in _vertex_rows(rows_of, chain[i]) if r >= border)
    return tuple(sorted(out))


def _chains(attach, segments, obj):
    """Per line, the vertices of its nodes from end A to end B (`obj` of each
    end: a free point, a rigid group or None; its interior nodes)."""
    for k, ((a, b), N) in enumerate(zip(attach, segments)):
        yield [obj(a)] + [("n", k, i) for i in range(1, N)] + [obj(b)]


def _vertex_rows(rows_of, v):
    if v is None:
        return []
    if v[0] in ("p", "n"):
        return rows_of[v]
    return [x for kind, _, r0 in rows_of[v] for x in range(r0, r0 + (kind == "r") + 1)]


def _topology(points, attach, segments, rods, bodies, bending_on) -> _Topology:
    free = tuple(i for i, p in enumerate(points) if isinstance(p, FreePoint))
    held = tuple(i for i, p in enumerate(points) if isinstance(p, AbstractEnd))
    on_body = tuple(i for i, p in enumerate(points) if isinstance(p, BodyPoint))
    owner, trans, rot, parent, rod_frame = _frames_of(rods, bodies)
    has_dof = [t == "state" or r == "state" for t, r in zip(trans, rot)]
    # groups: a frame with degrees of freedom and those pinned to it
    group_of, groups = {}, []
    for f in range(len(owner)):
        if not has_dof[f]:
            continue
        p = parent[f]
        if p is not None and has_dof[p]:
            group_of[f] = group_of[p]
            groups[group_of[f]].append(f)
        else:
            group_of[f] = len(groups)
            groups.append(([p] if p is not None else []) + [f])

    def frame_object(f):
        return ("g", group_of[f]) if f in group_of else None

    # rigid slots: both ends of every rod, then the points on bodies
    slot_frame = [rod_frame[r] for r in range(len(rods)) for _ in range(2)]
    slot_frame += [1 + points[i].body for i in on_body]

    def obj(e):
        if isinstance(e, RodEnd):
            return frame_object(rod_frame[e.rod])
        if e in on_body:
            return frame_object(1 + points[e].body)
        return ("p", e) if e in free else None

    # State rows in Cuthill-McKee order of the network's graph (vertices: interior
    # nodes, free points, rigid groups; edges: segments): breadth first from a
    # peripheral vertex, so that the band stays narrow along chains and the
    # branches of a hub interleave (band about the number of branches, not the
    # length of one).
    vertices, adj = [], {}

    def vertex(v):
        if v is not None and v not in adj:
            adj[v] = []
            vertices.append(v)
        return v

    for chain in _chains(attach, segments, obj):
        for v in chain:
            vertex(v)
        for u, v in zip(chain[:-1], chain[1:]):
            if u is not None and v is not None and u != v:
                adj[u].append(v)
                adj[v].append(u)
    for i in free:
        vertex(("p", i))
    for g in range(len(groups)):
        vertex(("g", g))

    def assign(order):
        rows_of, n = {}, 0
        for o in order:
            if o[0] in ("p", "n"):
                rows_of[o] = [n]
                n += 1
            else:
                rr = []
                for f in groups[o[1]]:
                    if trans[f] == "state":
                        rr.append(("t", f, n))
                        n += 1
                    if rot[f] == "state":
                        rr.append(("r", f, n))
                        n += 2
                rows_of[o] = rr
        return rows_of, n

    # Two orderings: everything in one band, or the rigid groups' rows first as
    # the Jacobian's border and the lines' nodes in a band of their own (the
    # lines on a body then no longer interleave around it). A border row costs
    # at most 2 x 6 JVPs (its columns, and its rows where the band's JVPs cannot
    # give them: `bordered_jacobian`), a node of band width 3 x 6: the ordering
    # with the cheaper bound wins.
    rows_of, n = assign(_cuthill_mckee(vertices, adj))
    width, border = _band_width(rows_of, attach, segments, obj, bending_on), 0
    if groups:
        rest = [v for v in vertices if v[0] != "g"]
        adj_rest = {v: [u for u in adj[v] if u[0] != "g"] for v in rest}
        order = [("g", g) for g in range(len(groups))]
        b_rows, b_n = assign(order + _cuthill_mckee(rest, adj_rest))
        k = sum(len(_vertex_rows(b_rows, g)) for g in order)
        b_width = _band_width(b_rows, attach, segments, obj, bending_on, k)
        if 2 * k <= 3 * (width - b_width):
            rows_of, n, width, border = b_rows, b_n, b_width, k
    coupled, columns = (), []
    if border:
        coupled = _border_coupled(rows_of, attach, segments, obj, bending_on, border)
        # the border's entries in use: a rotation's second row holds only the
        # quaternion's scalar part
        for g in range(len(groups)):
            for kind, _, r0 in rows_of[("g", g)]:
                columns += range(6 * r0, 6 * r0 + 6)
                if kind == "r":
                    columns.append(6 * (r0 + 1))
    line_rows = [[rows_of[("n", k, i)][0] for i in range(1, N)]
                 for k, N in enumerate(segments)]  # fmt: skip
    n_state = n
    trans_row = [None] * len(owner)
    rot_rows = [None] * len(owner)
    for o, rr in rows_of.items():
        if o[0] == "g":
            for kind, f, row in rr:
                if kind == "t":
                    trans_row[f] = row
                else:
                    rot_rows[f] = (row, row + 1)
    dofs = []
    for frames in groups:
        k, d = 0, []
        for f in frames:
            t_s = r_s = None
            if trans[f] == "state":
                t_s, k = slice(k, k + 3), k + 3
            if rot[f] == "state":
                r_s, k = slice(k, k + 3), k + 3
            d.append((t_s, r_s))
        dofs.append(tuple(d))
    # slots: three-degree-of-freedom rows (free points, interior nodes), held
    # points, rigid slots
    tri_rows = sorted(
        [rows_of[("p", i)][0] for i in free] + [r for rr in line_rows for r in rr]
    )
    tri_slot = {row: j for j, row in enumerate(tri_rows)}
    n_tri = len(tri_rows)
    point_body = np.zeros(len(points), int)
    for i in free:
        point_body[i] = tri_slot[rows_of[("p", i)][0]]
    for j, i in enumerate(held):
        point_body[i] = n_tri + j
    rod_body = n_tri + len(held) + np.arange(2 * len(rods)).reshape(len(rods), 2)
    for j, i in enumerate(on_body):
        point_body[i] = n_tri + len(held) + 2 * len(rods) + j

    def slot(e):
        if isinstance(e, RodEnd):
            return rod_body[e.rod, 0 if e.end == "A" else 1]
        return point_body[e]

    body, node_line, prev, nxt, seg_lo, seg_line, end_a, end_b = ([] for _ in range(8))
    bend = {k: [] for k in _Bending.__dataclass_fields__}
    m = s = 0
    for k, ((a, b), N) in enumerate(zip(attach, segments)):
        rows = [slot(a)] + [tri_slot[r] for r in line_rows[k]] + [slot(b)]
        body += rows
        node_line += [k] * (N + 1)
        prev += [m] + [m + i - 1 for i in range(1, N + 1)]
        nxt += [m + i + 1 for i in range(N)] + [m + N]
        seg_lo += [m + i for i in range(N)]
        seg_line += [k] * N
        end_a.append(m)
        end_b.append(m + N)
        bend["inner_node"] += [m + i for i in range(1, N)]
        bend["inner_prev"] += [s + i - 1 for i in range(1, N)]
        bend["inner_next"] += [s + i for i in range(1, N)]
        if isinstance(a, RodEnd):
            bend["clamp_a_node"].append(m)
            bend["clamp_a_seg"].append(s)
            bend["clamp_a_rod"].append(a.rod)
            bend["clamp_a_sign"].append(1.0 if a.end == "B" else -1.0)
        if isinstance(b, RodEnd):
            bend["clamp_b_node"].append(m + N)
            bend["clamp_b_seg"].append(s + N - 1)
            bend["clamp_b_rod"].append(b.rod)
            bend["clamp_b_sign"].append(1.0 if b.end == "A" else -1.0)
        m += N + 1
        s += N
    arr = lambda x: np.asarray(x, dtype=np.int32)
    bending = _Bending(
        **{
            k: np.asarray(v, float) if k.endswith("sign") else arr(v)
            for k, v in bend.items()
        }
    )
    frames = _Frames(
        owner=tuple(owner),
        trans=tuple(trans),
        rot=tuple(rot),
        parent=tuple(parent),
        trans_row=tuple(trans_row),
        rot_rows=tuple(rot_rows),
        groups=tuple(tuple(g) for g in groups),
        dofs=tuple(dofs),
        rod_frame=tuple(rod_frame),
    )
    # the state rows of each group (a rigid slot stands for all of them)
    group_rows = [tuple(_vertex_rows(rows_of, ("g", g))) if ("g", g) in rows_of
                  else () for g in range(len(groups))]  # fmt: skip
    return _Topology(
        n_state=n_state,
        tri_rows=arr(tri_rows),
        body=arr(body),
        node_line=arr(node_line),
        prev=arr(prev),
        next=arr(nxt),
        seg_lo=arr(seg_lo),
        seg_line=arr(seg_line),
        end_a=arr(end_a),
        end_b=arr(end_b),
        free_rows=arr([point_body[i] for i in free]),
        free=free,
        held=held,
        on_body=on_body,
        point_body=arr(point_body),
        rod_body=arr(rod_body).reshape(len(rods), 2),
        slot_frame=arr(slot_frame),
        bending=bending,
        frames=frames,
        group_rows=tuple(group_rows),
        width=width,
        border=border,
        border_coupled=coupled,
        border_columns=tuple(sorted(columns)),
    )


def _solve3(M, f):
    """x = M^-1 f for a batch of 3 x 3 matrices `(n, 3, 3)` (Cramer's rule)."""
    c0 = jnp.cross(M[:, 1], M[:, 2])
    c1 = jnp.cross(M[:, 2], M[:, 0])
    c2 = jnp.cross(M[:, 0], M[:, 1])
    det = _dot(M[:, 0], c0)
    # rows of M^-1 transposed: inverse = [c0 c1 c2] / det (columns)
    inv = jnp.stack([c0, c1, c2], axis=-1) / det[:, None, None]
    return jnp.einsum("nij,nj->ni", inv, f)


class _State(eqx.Module):
    """Everything one evaluation computes (not user-facing)."""

    kin: ChainKinematics
    seg_tension: Array  # (S,) axial force incl. damping, N
    seg_strain: Array  # (S,)
    seg_l: Array  # unstretched segment lengths (S,)
    node_force: Array  # (M, 3) total force on each line node, N
    node_mass: Array  # (M, 3, 3) mass matrix of each line node, kg
    body_force: Array  # (B, 3)
    body_mass: Array  # (B, 3, 3)
    held_acc: Array  # (H, 3) accelerations of the held points
    held_pos: Array
    held_vel: Array
    lengths: Array  # unstretched lengths of the lines (n_lines,)
    curvature: Array | None  # (M,) bending curvature at the nodes, 1/m
    frames: list  # rigid.Frame of every rigid frame
    rods: list  # per rod: (end A, axis, length, frame)
    rigid_pos: Array  # (K, 3) positions of the rigid slots


class LineNetwork(AbstractModel):
    """Mooring lines of lumped masses between points (see the module docstring).

    **Arguments:**

    - `points`: tuple of point conditions: `FixedEnd`, `PrescribedEnd` (a table of
      positions), `MotionEnd` (a function of time), `FreePoint`.
    - `attach`: `((a, b), ...)` per line, the indices in `points` of its ends A and
      B (structure).
    - `segments`: number of segments N per line (structure, >= 1).
    - `L` (unstretched length, m), `d` (m), `w` (mass per length, kg/m), `EA` (N),
      `BA` (N s; < 0: minus the damping ratio), `Cd`, `Ca`, `CdAx`, `CaAx`: one
      value per line, shape `(n_lines,)` (array leaves: differentiable, vmappable).
    - `lengths`: per line, None or a `PiecewiseLinear` unstretched length L(t), m
      (hauling in or paying out; MoorDyn's SetLineUnstretchedLength/Vel).
      Default: all None (L constant).
    - `line_ids`, `point_ids`: labels (structure; default 1, 2, ...).
    - `EI`: bending stiffness per line, `(n_lines,)`, N m^2 (>= 0; MoorDyn's
      nodal bending moments, `jaxstring.lines.bending`), or None (default): no
      bending, and none of it is traced. A line end on a rod end is then clamped
      to the rod's axis, a line end on a point is a hinge.
    - `rods`: tuple of `Rod`s (default none); a line end names a rod end as
      `RodEnd(rod index, "A" | "B")` in `attach`.
    - `bodies`: tuple of `Body`s (`jaxstring.lines.bodies`; default none):
      rigid bodies with 6 degrees of freedom ("free"), held ("fixed"), moved by
      a prescribed motion ("coupled") or with a prescribed reference point and
      free rotation ("pinned", MoorDyn's CoupledPinned). Points on a body are
      `BodyPoint`s in `points`; rods on a body name it in `Rod.body`.
    - `body_motions`: per body, None or the `RigidMotion` of a coupled or pinned
      body (default: all None, held at their initial pose).
    """

    points: tuple
    attach: tuple = eqx.field(static=True)
    segments: tuple = eqx.field(static=True)
    L: Float[Array, " n"] = _param()
    d: Float[Array, " n"] = _param()
    w: Float[Array, " n"] = _param()
    EA: Float[Array, " n"] = _param()
    BA: Float[Array, " n"] = _param()
    Cd: Float[Array, " n"] = _param()
    Ca: Float[Array, " n"] = _param()
    CdAx: Float[Array, " n"] = _param()
    CaAx: Float[Array, " n"] = _param()
    lengths: tuple | None = None
    line_ids: tuple | None = eqx.field(static=True, default=None)
    point_ids: tuple | None = eqx.field(static=True, default=None)
    EI: Float[Array, " n"] | None = eqx.field(converter=_none_or_f64, default=None)
    rods: tuple = ()
    bodies: tuple = ()
    body_motions: tuple = ()
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = (Gravity, Buoyancy, AbstractChainLoad)

    def __check_init__(self):
        if not isinstance(self.points, tuple):
            raise ValueError(f"`points` must be a tuple; got {self.points!r}.")
        if not isinstance(self.bodies, tuple) or not all(
            isinstance(b, Body) for b in self.bodies
        ):
            raise ValueError(
                f"`bodies` must be a tuple of Bodies; got {self.bodies!r}."
            )
        nb = len(self.bodies)
        for i, p in enumerate(self.points):
            if not isinstance(p, (AbstractEnd, FreePoint, BodyPoint)):
                raise ValueError(
                    f"`points[{i}]` must be a FixedEnd, PrescribedEnd, MotionEnd, "
                    f"FreePoint or BodyPoint; got {p!r}."
                )
            if isinstance(p, BodyPoint) and not p.body < nb:
                valid = f"0..{nb - 1}" if nb else "none: `bodies` is empty"
                raise ValueError(
                    f"`points[{i}].body` must be a body index ({valid}); got {p.body}."
                )
        if not isinstance(self.rods, tuple) or not all(
            isinstance(r, Rod) for r in self.rods
        ):
            raise ValueError(f"`rods` must be a tuple of Rods; got {self.rods!r}.")
        if self.body_motions and len(self.body_motions) != nb:
            raise ValueError(
                f"`body_motions` must hold one entry per body ({nb}); got "
                f"{len(self.body_motions)}."
            )
        for b, m in enumerate(self.body_motions):
            if m is not None and (
                not isinstance(m, RigidMotion)
                or self.bodies[b].kind not in ("coupled", "pinned")
            ):
                raise ValueError(
                    f"`body_motions[{b}]` must be None or a RigidMotion of a coupled "
                    f"or pinned body; got {m!r} for a {self.bodies[b].kind!r} body."
                )
        n = len(self.attach)
        if n == 0 and not (self.rods or self.bodies):
            raise ValueError("`attach` must name at least one line (a, b).")
        if len(self.segments) != n:
            raise ValueError(
                f"`segments` must have one entry per line ({n}); got {self.segments!r}."
            )
        for j, r in enumerate(self.rods):
            if r.body is not None and not r.body < nb:
                valid = f"0..{nb - 1}" if nb else "none: `bodies` is empty"
                raise ValueError(
                    f"`rods[{j}].body` must be None or a body index ({valid}); got "
                    f"{r.body}."
                )
            if r.segments == 0:
                raise ValueError(
                    f"`rods[{j}]`: a zero-length rod (segments = 0) is not simulated; "
                    "valid: segments >= 1."
                )

        def valid_end(e):
            if isinstance(e, RodEnd):
                return (
                    isinstance(e.rod, int)
                    and 0 <= e.rod < len(self.rods)
                    and e.end in ("A", "B")
                )
            return isinstance(e, int) and 0 <= e < len(self.points)

        for k, ab in enumerate(self.attach):
            if (
                not isinstance(ab, tuple)
                or len(ab) != 2
                or not all(valid_end(e) for e in ab)
                or ab[0] == ab[1]
            ):
                raise ValueError(
                    f"`attach[{k}]` must be two different line ends: point indices in "
                    f"0..{len(self.points) - 1} or RodEnd(rod, 'A' | 'B') with rod in "
                    f"0..{len(self.rods) - 1}; got {ab!r}."
                )
            check_int(f"segments[{k}]", self.segments[k], 1)
        for name in _LINE_PARAMS:
            check_shape(name, getattr(self, name), (n,))
            check_finite(name, getattr(self, name))
        for name in ("L", "d", "w", "EA"):
            check_positive(name, getattr(self, name))
        for name in ("Cd", "Ca", "CdAx", "CaAx"):
            check_nonnegative(name, getattr(self, name))
        if self.lengths is not None:
            if len(self.lengths) != n or not all(
                s is None or isinstance(s, PiecewiseLinear) for s in self.lengths
            ):
                raise ValueError(
                    "`lengths` must hold one entry per line: None or a PiecewiseLinear "
                    f"unstretched length (m); got {self.lengths!r}."
                )
        if self.EI is not None:
            check_shape("EI", self.EI, (n,), "N m^2")
            check_nonnegative("EI", self.EI, "N m^2")

    # -- structure
    @property
    def n_lines(self) -> int:
        return len(self.attach)

    @property
    def topology(self) -> _Topology:
        return _topology(self.points, self.attach, self.segments, self.rods,
                         self.bodies, self.EI is not None)  # fmt: skip

    def state_shape(self):
        return (self.topology.n_state, 6)

    def project(self, y):
        return y

    def structure(self, effects):
        """The node band of the state's ordering (lines, free points and rigid
        objects placed next to the lines that reach them, or the rigid objects'
        rows first as the Jacobian's border where that needs fewer JVPs: see
        `_topology`), the (r, r') layout of the rows in the band (where no
        rotating row is in it), and a Jacobian per implicit stage (the stiff
        axial forces turn with the lines); BDF keeps its Jacobian across steps
        (mooring chains move slowly). Bending couples each node to the nodes two
        away along its line; a rigid object's rows couple to one another and to
        the nodes next to the line ends on it. The Newton blocks are eliminated
        sequentially (faster to compile and as fast to run for the chains
        measured)."""
        del effects
        top = self.topology
        rotating_in_band = bool(top.frames.groups) and not top.border
        return SolverStructure(
            bandwidth=top.width,
            second_order=0 if rotating_in_band else 3,
            stage_jacobians=True,
            border=top.border,
            border_coupled=top.border_coupled,
            border_columns=top.border_columns,
            sequential_elimination=True,
        )

    def damping_BA(self):
        """Internal damping BA per line, N s (MoorDyn: -zeta (L/N) sqrt(EA w) for a
        negative input -zeta, with L the line's initial unstretched length)."""
        N = jnp.asarray(self.segments, jnp.float64)
        ratio = -self.BA * self.L / N * jnp.sqrt(self.EA * self.w)
        return jnp.where(self.BA < 0, ratio, self.BA)

    def unstretched_lengths(self, t):
        """Unstretched length L(t) and its rate, per line, m and m/s."""
        if self.lengths is None:
            return self.L, jnp.zeros_like(self.L)
        vals, rates = [], []
        for k, s in enumerate(self.lengths):
            if s is None:
                vals.append(self.L[k])
                rates.append(jnp.zeros_like(self.L[k]))
            else:
                value, rate, _ = s.kinematics(t)
                vals.append(value)
                rates.append(rate)
        return jnp.stack(vals), jnp.stack(rates)

    def held_kinematics(self, t):
        """Positions, velocities, accelerations of the held points, `(H, 3)`
        each."""
        held = [self.points[i].kinematics(t) for i in self.topology.held]
        out = []
        for name in ("position", "velocity", "acceleration"):
            rows = [getattr(k, name) for k in held]
            out.append(jnp.stack(rows) if rows else jnp.zeros((0, 3)))
        return tuple(out)

    def _free_params(self):
        return self._point_params(self.topology.free)

    def _point_params(self, which):
        """Mass, volume, CdA and Ca of the points `which` (indices), `(P,)` each."""
        pts = [self.points[i] for i in which]
        if not pts:
            z = jnp.zeros((0,))
            return z, z, z, z
        stack = lambda name: jnp.stack([getattr(p, name) for p in pts])
        return stack("mass"), stack("volume"), stack("CdA"), stack("Ca")

    # -- rigid frames
    def _frame_start(self, f):
        """Initial origin and orientation of frame f."""
        kind, i = self.topology.frames.owner[f]
        if kind == "earth":
            return jnp.zeros(3), jnp.eye(3)
        if kind == "body":
            body = self.bodies[i]
            return body.position, rotation_matrix(body.rotation)
        rod = self.rods[i]
        if rod.body is None:
            return rod.end_a, jnp.eye(3)
        p, R = self._frame_start(1 + rod.body)
        return p + R @ rod.end_a, jnp.eye(3)

    def _rod_local(self, r):
        """End A and the unit axis of rod r in the coordinates of its frame (its
        body's or the earth's for a fixed rod, its own for the others)."""
        rod = self.rods[r]
        if rod.kind == "fixed":
            return rod.end_a, rod.axis()
        if rod.body is None:
            return jnp.zeros(3), rod.axis()
        _, R = self._frame_start(1 + rod.body)
        return jnp.zeros(3), R @ rod.axis()

    def initial_rigid_rows(self, y):
        """`y` with the rows of the rigid frames at their initial pose, at rest."""
        frames = self.topology.frames
        for f in range(len(frames.owner)):
            p0, R0 = self._frame_start(f)
            if frames.trans_row[f] is not None:
                y = y.at[frames.trans_row[f]].set(jnp.concatenate([p0, jnp.zeros(3)]))
            if frames.rot_rows[f] is not None:
                r1, r2 = frames.rot_rows[f]
                q = matrix_to_quat(R0)
                y = y.at[r1].set(jnp.concatenate([q[1:], jnp.zeros(3)]))
                y = y.at[r2].set(jnp.zeros(6).at[0].set(q[0]))
        return y

    def frames(self, t, y):
        """The kinematics (`rigid.Frame`) of every rigid frame at `(t, y)`; the
        accelerations are those of the prescribed motions (zero where the state
        moves the frame)."""
        top = self.topology
        fr = top.frames
        out = []
        z = jnp.zeros(3)
        for f in range(len(fr.owner)):
            p0, R0 = self._frame_start(f)
            kind, i = fr.owner[f]
            motion = None
            if kind == "rod":
                motion = self.rods[i].motion
            elif kind == "body" and self.body_motions:
                motion = self.body_motions[i]
            if motion is not None:
                mf = motion.frame(t, p0, R0)
            else:
                mf = Frame(p0, R0, z, z, z, z)
            p, v, a = p0, z, z
            if fr.trans[f] == "state":
                row = y[fr.trans_row[f]]
                p, v = row[:3], row[3:]
            elif fr.trans[f] == "motion":
                p, v, a = mf.position, mf.velocity, mf.acceleration
            elif fr.trans[f] == "pin":
                P = out[fr.parent[f]]
                rho = P.rotation @ self.rods[i].end_a
                p = P.position + rho
                v = P.velocity + jnp.cross(P.omega, rho)
                a = (P.acceleration + jnp.cross(P.alpha, rho)
                     + jnp.cross(P.omega, jnp.cross(P.omega, rho)))  # fmt: skip
            R, w, al = R0, z, z
            if fr.rot[f] == "state":
                r1, r2 = fr.rot_rows[f]
                q = jnp.concatenate([y[r2, :1], y[r1, :3]])
                R, w = quat_to_matrix(q), y[r1, 3:]
            elif fr.rot[f] == "motion":
                R, w, al = mf.rotation, mf.omega, mf.alpha
            out.append(Frame(p, R, v, w, a, al))
        return out

    def _rod_geometry(self, frames):
        """End A, unit axis, length and frame of every rod, in earth axes."""
        fr = self.topology.frames
        out = []
        for r, rod in enumerate(self.rods):
            f = fr.rod_frame[r]
            F = frames[f]
            local_a, axis0 = self._rod_local(r)
            a = F.position + F.rotation @ local_a
            q = F.rotation @ axis0
            out.append((a, q, rod.length, f))
        return out

    def _rigid_slots(self, frames, rods):
        """Positions and velocities of the rigid slots (rod ends, then points on
        bodies), `(K, 3)`."""
        pos, vel = [], []
        for a, q, L, f in rods:
            F = frames[f]
            va = F.velocity + jnp.cross(F.omega, a - F.position)
            pos += [a, a + L * q]
            vel += [va, va + jnp.cross(F.omega, L * q)]
        for i in self.topology.on_body:
            p = self.points[i]
            F = frames[1 + p.body]
            rho = F.rotation @ p.position
            pos.append(F.position + rho)
            vel.append(F.velocity + jnp.cross(F.omega, rho))
        if not pos:
            z = jnp.zeros((0, 3))
            return z, z
        return jnp.stack(pos), jnp.stack(vel)

    # -- one evaluation
    def _state(self, t, y, effects, env) -> _State:
        top = self.topology
        for e in effects:
            if not isinstance(e, self.accepts):
                raise ValueError(
                    "a LineNetwork takes chain loads (Gravity, Buoyancy, Drag, "
                    f"Seabed); got {type(e).__name__} in `effects`."
                )
        hp, hv, ha = self.held_kinematics(t)
        frames = self.frames(t, y) if (self.rods or self.bodies) else []
        rods = self._rod_geometry(frames)
        sp, sv = self._rigid_slots(frames, rods)
        tri = take_rows(y, top.tri_rows)
        Bp = jnp.concatenate([tri[:, :3], hp, sp], axis=0)
        Bv = jnp.concatenate([tri[:, 3:], hv, sv], axis=0)
        R, V = take_rows(Bp, top.body), take_rows(Bv, top.body)
        lo, hi = top.seg_lo, top.seg_lo + 1
        sl = top.seg_line
        R_lo, R_hi = take_rows(R, lo), take_rows(R, hi)
        qs, lstr, ldstr, _ = links(R_lo, R_hi, take_rows(V, lo), take_rows(V, hi))
        Lt, Ldot = self.unstretched_lengths(t)
        Nl = jnp.asarray(self.segments, jnp.float64)
        l = take_rows(Lt / Nl, sl)
        ldot = take_rows(Ldot / Nl, sl)
        strain = (lstr - l) / l
        rate = (ldstr - lstr * ldot / l) / l
        T = (
            take_rows(self.EA, sl) * jnp.maximum(strain, 0.0)
            + take_rows(self.damping_BA(), sl) * rate
        )
        M = top.body.shape[0]
        seg_f = T[:, None] * qs
        node_f = add_rows(M, lo, seg_f) - add_rows(M, hi, seg_f)
        F = submerged_fraction(R_lo[:, 2], R_hi[:, 2], qs, 0.5 * take_rows(self.d, sl))
        half = 0.5 * l
        length = add_rows(M, lo, half) + add_rows(M, hi, half)
        sub = add_rows(M, lo, half * F) + add_rows(M, hi, half * F)
        nl = top.node_line
        area = 0.25 * jnp.pi * self.d**2
        mass = take_rows(self.w, nl) * length
        volume = take_rows(area, nl) * sub
        q = unit(take_rows(R, top.next) - take_rows(R, top.prev))
        curvature = None
        if self.EI is not None:
            bend = top.bending
            if len(bend.clamp_a_node) or len(bend.clamp_b_node):
                axes = jnp.stack([g[1] for g in rods])
                t_a = bend.clamp_a_sign[:, None] * axes[bend.clamp_a_rod]
                t_b = bend.clamp_b_sign[:, None] * axes[bend.clamp_b_rod]
                # a clamped end node's axis is the rod's (MoorDyn)
                q = q.at[bend.clamp_a_node].set(t_a).at[bend.clamp_b_node].set(t_b)
            else:
                t_a = t_b = jnp.zeros((0, 3))
            f_bend, curvature = bending_forces(
                qs, lstr, take_rows(self.EI, sl), bend, t_a, t_b, M
            )
            node_f = node_f + f_bend
        # the points with loads of their own: free points and points on bodies
        loaded = top.free + top.on_body
        fm, fv, fcda, fca = self._point_params(loaded)
        slots = top.point_body[np.asarray(loaded, np.int32)]
        fp = take_rows(Bp, slots) if loaded else jnp.zeros((0, 3))
        fvel = take_rows(Bv, slots) if loaded else jnp.zeros((0, 3))
        kin = ChainKinematics(
            positions=R,
            velocities=V,
            tangents=q,
            mass=mass,
            volume=volume,
            length=length,
            wetted_length=sub,
            diameter=take_rows(self.d, nl),
            Cd=take_rows(self.Cd, nl),
            CdAx=take_rows(self.CdAx, nl),
            point_positions=fp,
            point_velocities=fvel,
            point_mass=fm,
            point_volume=fv,
            point_CdA=fcda,
        )
        point_f = jnp.zeros_like(fp)
        for e in effects:
            f = e.forces(t, kin, env)
            node_f = node_f + f.nodes
            point_f = point_f + f.points
        eye = jnp.eye(3)
        Q = q[:, :, None] * q[:, None, :]
        added = (env.rho_water * volume)[:, None, None] * (
            take_rows(self.Ca, nl)[:, None, None] * (eye - Q)
            + take_rows(self.CaAx, nl)[:, None, None] * Q
        )
        node_m = mass[:, None, None] * eye + added
        nB = top.n_bodies
        body_f = add_rows(nB, top.body, node_f)
        body_m = add_rows(nB, top.body, node_m)
        if loaded:
            body_f = body_f + add_rows(nB, slots, point_f)
            pm = fm + env.rho_water * fv * fca
            body_m = body_m + add_rows(nB, slots, pm[:, None, None] * eye)
        return _State(
            kin=kin,
            seg_tension=T,
            seg_strain=strain,
            seg_l=l,
            node_force=node_f,
            node_mass=node_m,
            body_force=body_f,
            body_mass=body_m,
            held_acc=ha,
            held_pos=hp,
            held_vel=hv,
            lengths=Lt,
            curvature=curvature,
            frames=frames,
            rods=rods,
            rigid_pos=sp,
        )

    def _rod_loads(self, st, r, t, effects, env):
        """MoorDyn's loads on rod r at the state's pose (`rods.rod_loads`)."""
        loads = {}
        for e in effects:
            if isinstance(e, Gravity):
                loads["gravity"] = e
            elif isinstance(e, Buoyancy):
                loads["buoyancy"] = e
            elif isinstance(e, Drag):
                loads["drag"] = e
            elif isinstance(e, Seabed):
                loads["seabed"] = e
        a, q, _, f = st.rods[r]
        F = st.frames[f]
        va = F.velocity + jnp.cross(F.omega, a - F.position)
        return rod_loads(self.rods[r], a, q, va, F.omega, t, env, loads)

    def _rates(self, t, y, st: _State, effects, env):
        """dy/dt, the acceleration of every slot `(n_bodies, 3)`, and the
        translational and angular accelerations of every rigid frame."""
        top = self.topology
        n_tri, start = top.n_tri, top.rigid_start
        acc = _solve3(st.body_mass[:n_tri], st.body_force[:n_tri])
        tri = take_rows(y, top.tri_rows)
        # the rows are distinct: added to zeros, set
        dy = add_rows(y.shape[0], top.tri_rows, jnp.concatenate([tri[:, 3:], acc], 1))
        if not (self.rods or self.bodies):
            return dy, jnp.concatenate([acc, st.held_acc], axis=0), [], []
        fr = top.frames
        frames = list(st.frames)
        acc_f = [F.acceleration for F in frames]
        alp_f = [F.alpha for F in frames]
        for g, members in enumerate(fr.groups):
            local = {f: k for k, f in enumerate(members)}
            dofs = fr.dofs[g]
            parents = [local.get(fr.parent[f]) for f in members]
            pins = []
            for f in members:
                p = fr.parent[f]
                pins.append(None if p is None else frames[f].position
                            - frames[p].position)  # fmt: skip
            sets, rots = [], []
            for f in members:
                kind, b = fr.owner[f]
                if kind == "body" and fr.has_dof(f):
                    pos, mass, force, inertia, moment = self._body_loads(
                        b, frames[f], t, effects, env
                    )
                    sets.append(PointSet(local[f], pos, mass, force))
                    rots.append(Rotational(local[f], inertia, moment))
            for r in range(len(self.rods)):
                f = fr.rod_frame[r]
                if f in local and fr.has_dof(f):
                    ld = self._rod_loads(st, r, t, effects, env)
                    sets.append(PointSet(local[f], ld.positions, ld.masses, ld.forces))
                    rots.append(Rotational(local[f], ld.inertia, ld.moment))
            for f in members:
                on = np.nonzero(top.slot_frame == f)[0]
                if len(on) and fr.has_dof(f):
                    k = start + on
                    pset = PointSet(
                        local[f],
                        take_rows(st.rigid_pos, on),
                        take_rows(st.body_mass, k),
                        take_rows(st.body_force, k),
                    )
                    sets.append(pset)
            _, acc_g, alp_g = group_accelerations(
                [frames[f] for f in members], dofs, parents, pins, sets, rots
            )
            for f, k in local.items():
                acc_f[f], alp_f[f] = acc_g[k], alp_g[k]
                F = frames[f]
                # a frame's rows of dy are zero so far: set by adding
                n = dy.shape[0]
                if fr.trans[f] == "state":
                    row = jnp.concatenate([F.velocity, acc_g[k]])
                    dy = dy + add_rows(n, [fr.trans_row[f]], row[None])
                if fr.rot[f] == "state":
                    r1, r2 = fr.rot_rows[f]
                    qd = quat_rate(jnp.concatenate([y[r2, :1], y[r1, :3]]), F.omega)
                    row1 = jnp.concatenate([qd[1:], alp_g[k]])
                    row2 = jnp.concatenate([qd[:1], jnp.zeros(5)])
                    rows = jnp.stack([row1, row2])
                    dy = dy + add_rows(n, [r1, r2], rows)
        # accelerations of the rigid slots
        pos = st.rigid_pos
        slot_acc = [jnp.zeros((0, 3))]
        for s in range(top.slot_frame.shape[0]):
            f = int(top.slot_frame[s])
            F = frames[f]
            rho = pos[s] - F.position
            a = acc_f[f] + jnp.cross(alp_f[f], rho)
            slot_acc.append((a + jnp.cross(F.omega, jnp.cross(F.omega, rho)))[None])
        body_acc = jnp.concatenate([acc, st.held_acc] + slot_acc, axis=0)
        return dy, body_acc, acc_f, alp_f

    def _body_loads(self, b, F, t, effects, env):
        """Body b's own mass and loads (MoorDyn's Body): its mass at its centre of
        gravity with its weight and its buoyancy rho V g (MoorDyn puts the
        buoyancy there too: the deck has no centre of buoyancy), its added mass
        rho V R diag(Ca) R^T and translational drag 1/2 rho R diag(CdA) R^T |u| u
        at the reference point, and its rotational inertia R diag(I) R^T about
        the centre of gravity with the rotational drag -1/2 rho R diag(CdA_rot)
        R^T |omega| omega. Returns positions `(2, 3)`, masses `(2, 3, 3)`,
        forces `(2, 3)`, the inertia `(3, 3)` and the moment `(3,)`."""
        body = self.bodies[b]
        R, p = F.rotation, F.position
        rho, g = env.rho_water, env.g
        eye = jnp.eye(3)
        cg = p + R @ body.cg
        added = rho * body.volume * (R * body.Ca[None, :]) @ R.T
        f_cg = jnp.zeros(3)
        f_ref = jnp.zeros(3)
        moment = jnp.zeros(3)
        for e in effects:
            if isinstance(e, Gravity):
                f_cg = f_cg - body.mass * g * eye[2]
            elif isinstance(e, Buoyancy):
                f_cg = f_cg + rho * body.volume * g * eye[2]
            elif isinstance(e, Drag):
                u = -F.velocity
                if env.current is not None:
                    u = u + env.current(t, p[None])[0]
                Ct = (R * body.CdA[None, :3]) @ R.T
                Cr = (R * body.CdA[None, 3:]) @ R.T
                f_ref = f_ref + 0.5 * rho * e.scale * safe_norm(u) * (Ct @ u)
                moment = moment - 0.5 * rho * e.scale * safe_norm(F.omega) * (
                    Cr @ F.omega
                )
        pos = jnp.stack([cg, p])
        mass = jnp.stack([body.mass * eye, added])
        force = jnp.stack([f_cg, f_ref])
        inertia = (R * body.inertia[None, :]) @ R.T
        return pos, mass, force, inertia, moment

    def vector_field(self, t, y, effects, env):
        st = self._state(t, y, effects, env)
        return self._rates(t, y, st, effects, env)[0]

    def end_forces(self, st: _State, body_acc):
        """Forces of each line on its end points A and B, `(n_lines, 3)` each, N:
        the end node's segment force and loads less its inertia (it moves with the
        point); `body_acc` the accelerations of the slots (`_rates`)."""
        top = self.topology

        def at(nodes):
            a = take_rows(body_acc, top.body[nodes])
            inertia = jnp.einsum("nij,nj->ni", take_rows(st.node_mass, nodes), a)
            return take_rows(st.node_force, nodes) - inertia

        return at(top.end_a), at(top.end_b)

    def observables(self, t, y, effects, env):
        """`nodes` (every line node, `(M, 3)`, m), `node_velocities`, segment
        `tension` (`(S,)`, N, incl. damping) and `strain`, `end_force_a`,
        `end_force_b` (`(n_lines, 3)`, N, on the points) and their magnitudes
        `tension_a`, `tension_b` (`(n_lines,)`), `point_force` (net force of the
        lines on each point, `(n_points, 3)`), `lengths` (unstretched, m),
        `positions` (the state rows' first three columns, `(n, 3)`) and `energy`
        (kinetic + elastic + the potentials of the scene's constant loads, weight
        and buoyancy, J; without bending, whose nodal forces have no potential,
        and only for networks without rods). With rods: `rod_end_force` (the
        lines' force on each rod's ends A and B, `(R, 2, 3)`, N), `rod_end_a`,
        `rod_axis`, `rod_velocity`, `rod_acceleration` (of end A), `rod_omega`,
        `rod_alpha` (`(R, 3)`), `rod_force` (`(R, 6)`: force, N, and moment about
        end A, N m, of everything on the rod; less its inertia for a coupled rod),
        `rod_end_tension` (`(R, 2)`, N: the magnitude of the lines' end-node
        forces on ends A and B, MoorDyn's TENA, TENB), `rod_nodes` and
        `rod_node_force` (every rod node, rod by rod, see `rod_nodes`); with
        bodies, per body: `body_position`, `body_velocity`,
        `body_acceleration` (of its reference point, `(B, 3)`),
        `body_rotation` (`(B, 3, 3)`, body to earth), `body_angles` (MoorDyn's
        Euler angles, rad), `body_omega`, `body_alpha` (`(B, 3)`) and
        `body_force` (`(B, 6)`: force, N, and moment about the reference point,
        N m, MoorDyn's getFnet, see `_body_observables`); with
        bending stiffness: `curvature` at every line node
        (`(M,)`, 1/m)."""
        st = self._state(t, y, effects, env)
        _, body_acc, acc_f, alp_f = self._rates(t, y, st, effects, env)
        fa, fb = self.end_forces(st, body_acc)
        top = self.topology
        pf = jnp.zeros((len(self.points), 3))
        rf = jnp.zeros((2 * len(self.rods), 3))
        for side, f in ((0, fa), (1, fb)):
            ends = [ab[side] for ab in self.attach]
            at_point = [k for k, e in enumerate(ends) if not isinstance(e, RodEnd)]
            at_rod = [k for k, e in enumerate(ends) if isinstance(e, RodEnd)]
            if at_point:
                idx = np.asarray([ends[k] for k in at_point])
                pf = pf + add_rows(pf.shape[0], idx, take_rows(f, at_point))
            if at_rod:
                idx = np.asarray(
                    [2 * ends[k].rod + (ends[k].end == "B") for k in at_rod]
                )
                rf = rf + add_rows(rf.shape[0], idx, take_rows(f, at_rod))
        kin = st.kin
        out = {
            "nodes": kin.positions,
            "node_velocities": kin.velocities,
            "positions": y[:, :3],
            "tension": st.seg_tension,
            "strain": st.seg_strain,
            "end_force_a": fa,
            "end_force_b": fb,
            "tension_a": safe_norm(fa),
            "tension_b": safe_norm(fb),
            "point_force": pf,
            "lengths": st.lengths,
        }
        if not (self.rods or self.bodies):
            v = y[:, 3:]
            ke = 0.5 * jnp.sum(
                jnp.einsum("ni,nij,nj->n", v, st.body_mass[: top.n_state], v)
            )
            EAs = take_rows(self.EA, top.seg_line)
            strain = jnp.maximum(st.seg_strain, 0.0)
            elastic = 0.5 * jnp.sum(EAs * st.seg_l * strain**2)
            # The potential of the constant loads (weight, buoyancy): minus their
            # work, over the nodes that move (not those on held points) and the
            # free points.
            pot = jnp.zeros(())
            inner = np.ones(top.body.shape[0], bool)
            inner[top.body >= top.n_state] = False
            for e in effects:
                if e.constant:
                    f = e.forces(t, kin, env)
                    work = jnp.where(inner, _dot(f.nodes, kin.positions), 0.0)
                    pot = (pot - jnp.sum(work)
                           - jnp.sum(_dot(f.points, kin.point_positions)))  # fmt: skip
            out["energy"] = ke + elastic + pot
        if self.rods:
            out.update(self._rod_observables(t, st, body_acc, acc_f, alp_f,
                                             effects, env))  # fmt: skip
            out["rod_end_force"] = rf.reshape(len(self.rods), 2, 3)
        if self.bodies:
            out.update(self._body_observables(t, st, acc_f, alp_f, effects, env))
        if st.curvature is not None:
            out["curvature"] = st.curvature
        return out

    def _rod_observables(self, t, st, body_acc, acc_f, alp_f, effects, env):
        """Per rod: end A's position, velocity and acceleration, the axis, the
        angular velocity and acceleration, every node, and the net force and
        moment about end A of everything on it (its loads and the end nodes of
        its lines: MoorDyn's F6net), less its inertia for a coupled rod (the
        force its motion takes: MoorDyn's getFnet)."""
        top = self.topology
        ends = [[] for _ in range(2 * len(self.rods))]
        for k, (a, b) in enumerate(self.attach):
            for e, node in ((a, top.end_a[k]), (b, top.end_b[k])):
                if isinstance(e, RodEnd):
                    ends[2 * e.rod + (e.end == "B")].append(int(node))
        out = {k: [] for k in ("rod_end_a", "rod_axis", "rod_velocity", "rod_omega",
                               "rod_acceleration", "rod_alpha", "rod_force",
                               "rod_nodes", "rod_node_force",
                               "rod_end_tension")}  # fmt: skip
        for r, rod in enumerate(self.rods):
            a, q, L, f = st.rods[r]
            F = st.frames[f]
            ld = self._rod_loads(st, r, t, effects, env)
            pos, force, mass = ld.positions, ld.forces, ld.masses
            # the lines' end nodes at its ends
            for side, idx in ((0, ends[2 * r]), (-1, ends[2 * r + 1])):
                if idx:
                    nodes = np.asarray(idx)
                    force = force.at[side].add(
                        jnp.sum(take_rows(st.node_force, nodes), 0)
                    )
                    mass = mass.at[side].add(jnp.sum(take_rows(st.node_mass, nodes), 0))
            rho = pos - a
            F6 = jnp.concatenate(
                [jnp.sum(force, 0), jnp.sum(jnp.cross(rho, force), 0) + ld.moment]
            )
            w = F.omega
            rho_f = pos - F.position
            acc = (acc_f[f] + jnp.cross(alp_f[f], rho_f)
                   + jnp.cross(w, jnp.cross(w, rho_f)))  # fmt: skip
            if rod.kind in ("coupled", "coupled_pinned"):
                inert = jnp.einsum("kij,kj->ki", mass, acc)
                Fi = jnp.sum(inert, 0)
                Mi = (jnp.sum(jnp.cross(rho, inert), 0) + ld.inertia @ alp_f[f]
                      + jnp.cross(w, ld.inertia @ w))  # fmt: skip
                if rod.kind == "coupled":
                    F6 = F6 - jnp.concatenate([Fi, Mi])
                else:
                    F6 = jnp.concatenate([F6[:3] - Fi, jnp.zeros(3)])
            out["rod_end_a"].append(a)
            out["rod_axis"].append(q)
            out["rod_velocity"].append(F.velocity + jnp.cross(w, a - F.position))
            out["rod_acceleration"].append(acc[0])
            out["rod_omega"].append(w)
            out["rod_alpha"].append(alp_f[f])
            out["rod_force"].append(F6)
            out["rod_nodes"].append(pos)
            out["rod_node_force"].append(force)
            out["rod_end_tension"].append(jnp.stack([
                safe_norm(jnp.sum(take_rows(st.node_force, np.asarray(ix, int)), 0))
                if ix else jnp.zeros(()) for ix in (ends[2 * r], ends[2 * r + 1])
            ]))  # fmt: skip
        stack = {k: jnp.stack(v) for k, v in out.items()
                 if k not in ("rod_nodes", "rod_node_force")}  # fmt: skip
        stack["rod_nodes"] = jnp.concatenate(out["rod_nodes"])
        stack["rod_node_force"] = jnp.concatenate(out["rod_node_force"])
        del body_acc
        return stack

    def _frame_sets(self, st, f, t, effects, env):
        """What moves rigidly with frame f: lumped masses `(positions, masses,
        forces)` and rotational inertias `(inertia, moment)` (its body's or
        rod's own, its fixed rods', its points and rod ends with the lines on
        them)."""
        top, fr = self.topology, self.topology.frames
        sets, rots = [], []
        kind, i = fr.owner[f]
        if kind == "body":
            pos, mass, force, inertia, moment = self._body_loads(
                i, st.frames[f], t, effects, env
            )
            sets.append((pos, mass, force))
            rots.append((inertia, moment))
        for r in range(len(self.rods)):
            if fr.rod_frame[r] == f:
                ld = self._rod_loads(st, r, t, effects, env)
                sets.append((ld.positions, ld.masses, ld.forces))
                rots.append((ld.inertia, ld.moment))
        on = np.nonzero(top.slot_frame == f)[0]
        if len(on):
            k = top.rigid_start + on
            sets.append((st.rigid_pos[on], st.body_mass[k], st.body_force[k]))
        return sets, rots

    def _body_observables(self, t, st, acc_f, alp_f, effects, env):
        """Per body: the reference point's position, velocity and acceleration,
        the rotation (body to earth) and MoorDyn's Euler angles of it, the
        angular velocity and acceleration, and MoorDyn's net force and moment
        about the reference point (`getFnet`): of everything on the body (its
        own loads, its points and rods with the lines on them, the pin forces of
        rods pinned to it), less its inertia for a coupled body, and less the
        inertia force with no moment for a pinned body."""
        fr = self.topology.frames
        frames = st.frames

        def accel(f, pos):
            F = frames[f]
            rho = pos - F.position
            return (acc_f[f] + jnp.cross(alp_f[f], rho)
                    + jnp.cross(F.omega, jnp.cross(F.omega, rho)))  # fmt: skip

        out = {k: [] for k in ("body_position", "body_rotation", "body_angles",
                               "body_velocity", "body_omega", "body_acceleration",
                               "body_alpha", "body_force")}  # fmt: skip
        for b, body in enumerate(self.bodies):
            f = 1 + b
            F = frames[f]
            sets, rots = self._frame_sets(st, f, t, effects, env)
            force, moment = jnp.zeros(3), jnp.zeros(3)
            f_in, m_in = jnp.zeros(3), jnp.zeros(3)
            for pos, mass, fk in sets:
                rho = pos - F.position
                inert = jnp.einsum("kij,kj->ki", mass, accel(f, pos))
                force = force + jnp.sum(fk, 0)
                moment = moment + jnp.sum(jnp.cross(rho, fk), 0)
                f_in = f_in + jnp.sum(inert, 0)
                m_in = m_in + jnp.sum(jnp.cross(rho, inert), 0)
            for inertia, tau in rots:
                moment = moment + tau
                m_in = m_in + inertia @ alp_f[f] + jnp.cross(F.omega, inertia @ F.omega)
            # rods pinned to the body: the force through the pin
            for c in range(len(fr.owner)):
                if fr.parent[c] != f:
                    continue
                csets, _ = self._frame_sets(st, c, t, effects, env)
                pin = jnp.zeros(3)
                for pos, mass, fk in csets:
                    inert = jnp.einsum("kij,kj->ki", mass, accel(c, pos))
                    pin = pin + jnp.sum(fk - inert, 0)
                force = force + pin
                moment = moment + jnp.cross(frames[c].position - F.position, pin)
            F6 = jnp.concatenate([force, moment])
            if body.kind == "coupled":
                F6 = F6 - jnp.concatenate([f_in, m_in])
            elif body.kind == "pinned":
                F6 = jnp.concatenate([force - f_in, jnp.zeros(3)])
            out["body_position"].append(F.position)
            out["body_rotation"].append(F.rotation)
            out["body_angles"].append(euler_angles(F.rotation))
            out["body_velocity"].append(F.velocity)
            out["body_omega"].append(F.omega)
            out["body_acceleration"].append(acc_f[f])
            out["body_alpha"].append(alp_f[f])
            out["body_force"].append(F6)
        return {k: jnp.stack(v) for k, v in out.items()}

    def rod_nodes(self, r: int) -> np.ndarray:
        """Indices of rod `r`'s nodes (A to B) in the `rod_nodes` observable."""
        start = sum(rod.segments + 1 for rod in self.rods[:r])
        return np.arange(start, start + self.rods[r].segments + 1)

    def line_nodes(self, k: int) -> np.ndarray:
        """Indices of line `k`'s nodes (A to B) in the `nodes` observable."""
        start = sum(N + 1 for N in self.segments[:k])
        return np.arange(start, start + self.segments[k] + 1)


# ---------------------------------------------------------------------------
# Static equilibrium


def _catenary(pa, pb, L, w, N, seabed_z, EA):
    """Node positions `(N + 1, 3)` of an inextensible catenary of length L and
    weight w per length (N/m) from pa to pb, lying on the plane z = seabed_z from
    the lower end where it reaches it; plus the largest tension estimate, N.
    A taut or weightless line is straight."""
    pa, pb = np.asarray(pa, float), np.asarray(pb, float)
    s = np.linspace(0.0, L, N + 1)
    D = np.linalg.norm(pb - pa)
    flip = pb[2] < pa[2]
    lo, hi = (pb, pa) if flip else (pa, pb)
    dh = hi[:2] - lo[:2]
    X = float(np.hypot(*dh))
    H = float(hi[2] - lo[2])
    if abs(w) * L < 1e-6 * EA or L <= D * (1 + 1e-9) or X < 1e-6 * L:
        return pa + np.outer(s / L, pb - pa), 0.0
    sign = 1.0 if w > 0 else -1.0
    e = np.append(dh / X, 0.0)
    Hs = sign * H  # height in the frame where the line sags downwards

    def place(x, z):
        pts = lo + np.outer(x, e) + np.outer(sign * z, [0, 0, 1.0])
        return pts[::-1] if flip else pts

    on_bed = w > 0 and seabed_z is not None and lo[2] <= seabed_z + 1e-6 and Hs > 0
    if on_bed and L - X > 0:
        # touchdown: Ls suspended with a horizontal tangent at its foot
        def g(Ls):
            a = (Ls**2 - Hs**2) / (2 * Hs)
            return Ls - (L - X) - a * math.asinh(Ls / a)

        a_lo, a_hi = Hs * (1 + 1e-12), L
        if g(a_hi) * g(a_lo) < 0:
            s_lo = g(a_lo) < 0
            for _ in range(200):
                mid = 0.5 * (a_lo + a_hi)
                a_lo, a_hi = (mid, a_hi) if (g(mid) < 0) == s_lo else (a_lo, mid)
            Ls = 0.5 * (a_lo + a_hi)
            Lb = L - Ls
            a = (Ls**2 - Hs**2) / (2 * Hs)
            sp = np.maximum(s - Lb, 0.0)
            x = np.minimum(s, Lb) + a * np.arcsinh(sp / a)
            z = a * (np.cosh(np.maximum(x - Lb, 0.0) / a) - 1.0)
            return place(x, z), abs(w) * (a + Hs)
    # fully suspended: sqrt(L^2 - H^2) = 2 a sinh(X / (2 a))
    target = math.sqrt(max(L**2 - Hs**2, 1e-300))
    lo_a, hi_a = 1e-6 * X, 1e9 * X
    for _ in range(300):
        mid = math.sqrt(lo_a * hi_a)
        if 2 * mid * math.sinh(min(X / (2 * mid), 700.0)) > target:
            lo_a = mid
        else:
            hi_a = mid
    a = math.sqrt(lo_a * hi_a)
    x0 = X / 2 - a * math.asinh(Hs / (2 * a * math.sinh(X / (2 * a))))
    s0 = math.sinh(-x0 / a)
    x = x0 + a * np.arcsinh(s / a + s0)
    z = a * (np.cosh((x - x0) / a) - math.cosh(-x0 / a))
    return place(x, z), abs(w) * a * math.cosh((X - x0) / a)


def initial_shape(model: LineNetwork, effects=(), env=None, t0=0.0):
    """A state at rest: every line a catenary between its points at time `t0`
    (free points at their given positions), lying on the seabed of a `Seabed`
    effect where it reaches it, drawn with the length stretched by the
    catenary's largest tension. The starting point of `equilibrium`.

    **Returns:** state `(n, 6)`."""
    env = Environment() if env is None else env
    top = model.topology
    t0 = f64(t0)
    hp, ends, L = (np.asarray(a) for a in _start_geometry(model, t0))
    pos = np.zeros((top.n_state, 3))
    pts = []
    for i, p in enumerate(model.points):
        if isinstance(p, FreePoint):
            pts.append(np.asarray(p.position))
        elif isinstance(p, BodyPoint):
            pts.append(ends[2 * len(model.rods) + top.on_body.index(i)])
        else:
            pts.append(hp[top.held.index(i)])
    for i, r in zip(top.free, top.free_rows):
        pos[top.tri_rows[r]] = pts[i]

    def at(e):
        if isinstance(e, RodEnd):
            return ends[2 * e.rod + (e.end == "B")]
        return pts[e]

    bed = [e for e in effects if isinstance(e, Seabed)]
    seabed_z = -float(bed[0].depth) if bed else None
    gravity = any(isinstance(e, Gravity) for e in effects)
    buoyancy = any(isinstance(e, Buoyancy) for e in effects)
    g, rho = float(env.g), float(env.rho_water)
    # (read on the host: an eager index of a JAX array compiles a program)
    ds, ws, EAs = (np.asarray(a) for a in (model.d, model.w, model.EA))
    for k, ((a, b), N) in enumerate(zip(model.attach, model.segments)):
        d = float(ds[k])
        w = (float(ws[k]) * gravity - rho * 0.25 * math.pi * d**2 * buoyancy) * g
        EA = float(EAs[k])
        _, T = _catenary(at(a), at(b), float(L[k]), w, N, seabed_z, EA)
        # the stretched line: the catenary of the length under that tension
        stretched = float(L[k]) * (1.0 + max(T, 0.0) / EA)
        shape, _ = _catenary(at(a), at(b), stretched, w, N, seabed_z, EA)
        rows = top.tri_rows[top.body[model.line_nodes(k)[1:-1]]]
        pos[rows] = shape[1:-1]
    y = jax.device_put(np.concatenate([pos, np.zeros_like(pos)], axis=1))
    if not len(top.frames.owner):
        return y
    return _with_rigid_rows(model, y)


# The start's geometry in one compiled call: op by op, the motion tables'
# interpolation alone compiled some fifty one-operation programs.
@eager_jit(tiered=True)
def _start_geometry(model: LineNetwork, t0):
    """Held points' positions, rod ends and points on bodies, unstretched
    lengths at `t0`."""
    top = model.topology
    hp = model.held_kinematics(t0)[0]
    ends = jnp.zeros((0, 3))
    if model.rods or model.bodies:
        rigid = model.initial_rigid_rows(jnp.zeros((top.n_state, 6)))
        frames = model.frames(t0, rigid)
        ends = model._rigid_slots(frames, model._rod_geometry(frames))[0]
    return hp, ends, model.unstretched_lengths(t0)[0]


@eager_jit(tiered=True)
def _with_rigid_rows(model: LineNetwork, y):
    return model.initial_rigid_rows(y)


def _equilibrium_residual(x, model, effects, env, t0, solve_rows):
    y = jnp.concatenate([x, jnp.zeros_like(x)], axis=1)
    st = model._state(t0, y, effects, env)
    top = model.topology
    # distinct rows: added to zeros, set
    f = add_rows(x.shape[0], top.tri_rows, st.body_force[: top.n_tri])
    return jnp.where(solve_rows[:, None], f, 0.0)


def _ptc(x0, model, effects, env, t0, solve_rows, max_iter, tol, ftol):
    """Pseudo-transient continuation to a zero of the net forces: implicit Euler
    steps of x' = F(x) with a step that grows as the residual falls (a Newton
    iteration once it is large). Returns (x, residual norm, iterations, the
    Jacobian dF/dx at x).

    Each pass of the loop evaluates the forces and their Jacobian together, once,
    at the trial point x + dx (the Jacobian is kept where the point is accepted),
    so that the compiled program holds one copy of the forces' Jacobian and none
    of the forces alone; the first pass evaluates the start."""

    def resid(xf):
        return _equilibrium_residual(
            xf.reshape(x0.shape), model, effects, env, t0, solve_rows
        ).reshape(-1)

    def resid_and_jacobian(xf):
        J, r = jax.jacfwd(lambda z: (lambda f: (f, f))(resid(z)), has_aux=True)(xf)
        return r, J

    mask = jnp.repeat(solve_rows, 3).astype(jnp.float64)

    def update(r, J, dt):
        A = jnp.diag(mask / dt + (1 - mask)) - J * mask[:, None]
        return jnp.linalg.solve(A, r) * mask

    def body(c):
        x, r, J, dt, it, _, dx, first = c
        xn = x + dx
        rn, Jn = resid_and_jacobian(xn)
        nr, nrn = jnp.linalg.norm(r), jnp.linalg.norm(rn)
        ok = first | (jnp.isfinite(nrn) & (nrn < 2.0 * nr + 1e-300))
        grow = jnp.clip(nr / jnp.maximum(nrn, 1e-300), 0.1, 10.0)
        dt_new = jnp.minimum(jnp.where(ok, dt * grow, dt * 0.1), 1 / _MIN_STIFFNESS)
        dt_new = jnp.where(first, dt, dt_new)
        step = jnp.where(ok & ~first, jnp.max(jnp.abs(dx)), jnp.inf)
        x = jnp.where(ok, xn, x)
        r = jnp.where(ok, rn, r)
        J = jnp.where(ok, Jn, J)
        it = it + jnp.where(first, 0, 1)
        return (x, r, J, dt_new, it, step, update(r, J, dt_new), jnp.asarray(False))

    def cond(c):
        _, r, _, _, it, step, _, first = c
        return first | ((it < max_iter) & (step > tol) & (jnp.linalg.norm(r) > ftol))

    x0f = x0.reshape(-1)
    n = x0f.shape[0]
    init = (
        x0f,
        jnp.zeros(n),
        jnp.zeros((n, n)),
        jnp.asarray(1e-6),
        jnp.asarray(0),
        jnp.asarray(jnp.inf),
        jnp.zeros(n),
        jnp.asarray(True),
    )
    x, r, J, _, it, _, _, _ = jax.lax.while_loop(cond, body, init)
    return x.reshape(x0.shape), jnp.linalg.norm(r), it, J


# The pseudo-time term 1/dt never falls below this, N/m: a slack, weightless
# line has no stiffness at all, and its nodes then stay where they are.
_MIN_STIFFNESS = 1e-4


def _newton_step(x, J, model, effects, env, t0, solve_rows):
    """The converged `x` with the derivative of one (regularised) Newton step in
    the parameters: the implicit-function derivative of the equilibrium. `J`: the
    Jacobian dF/dx at `x` (the iteration's last, held constant)."""
    mask = jnp.repeat(solve_rows, 3).astype(jnp.float64)
    J = jax.lax.stop_gradient(J)
    A = jnp.diag(mask * _MIN_STIFFNESS + (1 - mask)) - J * mask[:, None]
    r = _equilibrium_residual(x, model, effects, env, t0, solve_rows).reshape(-1)
    dx = jnp.linalg.solve(A, r).reshape(x.shape)
    # The primal stays the converged x (the step would only amplify the residual
    # along the directions a slack line leaves free); the tangent is the step's.
    return x + (dx - jax.lax.stop_gradient(dx))


def _solve_equilibrium_body(x0, model, effects, env, t0, solve_rows, max_iter, tol):
    frozen = jax.lax.stop_gradient((model, effects, env))
    # Forces below 1e-9 of the total weight in water count as balanced.
    m, _, v = frozen
    area = 0.25 * jnp.pi * m.d**2
    weight = jnp.sum(jnp.abs(m.w - v.rho_water * area) * m.L)
    fm, fv, _, _ = m._free_params()
    weight = v.g * (weight + jnp.sum(jnp.abs(fm - v.rho_water * fv)))
    ftol = 1e-9 * jnp.maximum(weight, 1.0)
    x, res, it, J = _ptc(
        jax.lax.stop_gradient(x0), *frozen, t0, solve_rows, max_iter, tol, ftol
    )
    x = jax.lax.stop_gradient(x)
    x = _newton_step(x, J, model, effects, env, t0, solve_rows)
    return x, res, it, ftol, rest_end_tensions(model, effects, env, t0, x)


def rest_end_tensions(model, effects, env, t, x):
    """Per line, the (end A, end B) tension magnitudes `(n_lines,)` at rest with
    the state rows at positions `x` `(n, 3)`: the force each line exerts on its
    end points (segment tension plus the end node's loads), N."""
    y = jnp.concatenate([x, jnp.zeros_like(x)], axis=1)
    st = model._state(t, y, effects, env)
    fa, fb = model.end_forces(st, jnp.zeros((model.topology.n_bodies, 3)))
    return jnp.linalg.norm(fa, axis=1), jnp.linalg.norm(fb, axis=1)


_solve_equilibrium = cpu_jit(_solve_equilibrium_body, tiered=True)


@single_blas_thread
def equilibrium(
    model: LineNetwork,
    effects=(),
    env=None,
    t0=0.0,
    y0=None,
    free_points: str = "hold",
    max_iter: int = 500,
    tol: float = 1e-9,
):
    """The static equilibrium of a network: zero net force on every node at rest.

    Starts from `y0` (default: `initial_shape`) and runs pseudo-transient
    continuation (implicit Euler steps of x' = F(x), the step growing to a Newton
    step) with the dense Jacobian. The last step is a Newton step taken with the
    live parameters, so the returned state carries the implicit-function
    derivative dx/dtheta = -J^-1 dF/dtheta under `jax.grad` (the iteration itself
    is not differentiated).

    **Arguments:**

    - `free_points`: `"hold"` (free points stay where they are, MoorDyn's initial
      condition: the lines settle between them) or `"solve"` (they settle too).
    - `max_iter`: iteration limit. `tol`: largest position update at convergence, m.

    **Returns:** `(y, info)`: the state `(n, 6)` at rest and a dict with
    `residual` (the norm of the net forces, N), `iterations` and the lines' end
    tensions there, `tension_a` and `tension_b` (`(n_lines,)`, N). Raises
    ValueError when the iteration does not converge.
    """
    check_choice("free_points", free_points, ("hold", "solve"))
    env = Environment() if env is None else env
    effects = tuple(effects)
    top = model.topology
    # the rigid objects are held at their poses
    solve_rows = np.zeros(top.n_state, bool)
    solve_rows[top.tri_rows] = True
    if free_points == "hold":
        solve_rows[top.tri_rows[top.free_rows]] = False
    solve_rows = jax.device_put(solve_rows)
    if y0 is None:
        y0 = initial_shape(model, effects, env, t0)
    x0 = host_op(lambda xp, y: y[:, :3], y0)
    if isinstance(x0, jax.core.Tracer):
        x0 = jax.lax.stop_gradient(x0)
    t0 = f64(t0)
    # a later process skips tracing the solve (`jaxstring._programs`)
    x, res, it, ftol, (ta, tb) = _programs.call_or_jit(
        _solve_equilibrium_body,
        _solve_equilibrium,
        *(x0, model, effects, env, t0, solve_rows, max_iter, tol),
        tiered=True,
    )
    if not isinstance(res, jax.core.Tracer):
        if not np.isfinite(float(res)) or float(res) > 1e3 * float(ftol):
            raise ValueError(
                f"the static equilibrium did not converge: residual {float(res):.3g} N "
                f"after {int(it)} iterations (max_iter = {max_iter})."
            )
    y = host_op(lambda xp, x: xp.concatenate([x, xp.zeros_like(x)], axis=1), x)
    return y, {"residual": res, "iterations": it, "tension_a": ta, "tension_b": tb}
