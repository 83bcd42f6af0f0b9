r"""Static equilibrium and stiffness of a mooring system of analytic catenaries.

A `MooringSystem` is bodies (`Body`: 6 degrees of freedom), points
(`MooringPoint`: fixed, coupled, free, or fixed on a body) and lines between
points, each line an elastic catenary (`catenary_forces`: MoorPy's and MAP++'s
quasi-static line, Jonkman 2007) whose anchor end, when it lies on the seabed
$z = -$`depth`, lets the line rest on a flat seabed and slide there (with the
Coulomb friction `CB`, 0 by default). It is built from a MoorDyn deck
(`mooring_system`) or in Python.

`mooring_equilibrium(system, loads)` finds the pose where every free degree of
freedom is in balance under

- the line tensions at the points (a point on a body hands its force, and the
  moment about the body's reference point, to the body);
- weight and buoyancy: a body's weight $m g$ at its centre of gravity and the
  buoyancy $\rho_w g V$ of its displaced volume at its reference point (MoorDyn's
  documented convention; MoorPy's with `rM = 0`); a point's $(\rho_w V - m) g$;
- a body's optional linear hydrostatic stiffness $-K_h (q - q_h)$ (a 6x6 matrix
  per body on its pose $q$ = position and roll, pitch, yaw, about $q_h$: the
  waterplane stiffness of a surface-piercing body, which the displaced volume
  alone does not give; MoorPy's `AWP` is $K_h[2, 2] = \rho_w g A_{WP}$ about
  $z = 0$);
- steady loads (`MooringLoads`): a force and a moment (about the reference
  point, global axes) on each body, a force on each point.

Free bodies have 6 degrees of freedom (position, and a rotation vector from their
given orientation), pinned bodies 3 (rotation), free points 3. Coupled bodies and
points are held at their pose plus the given `offsets`; fixed ones stay.
Newton's method with the Jacobian by automatic differentiation and a
backtracking line search solves the balance, from the given pose or a guess, to a
residual relative to the system's force scale (`tol`); the result says whether it
converged, and why not (`message`), and never returns a pose that is not an
equilibrium without saying so.

`coupled_stiffness(system, loads)` is the stiffness of the coupled degrees of
freedom (6 per coupled body, 3 per pinned body and coupled point) with the free
ones re-balanced: $K = -(J_{cc} - J_{cf} J_{ff}^{-1} J_{fc})$, the Schur
complement of the Jacobian of the generalized forces (MoorPy's
`getCoupledStiffness`, which takes it by finite differences of re-solved
equilibria, and `getCoupledStiffnessA`, its Guyan reduction). Columns are
translations and small rotations about the global axes at the pose; rows are
forces and moments about the body's reference point, global axes. The
translational block is symmetric (the lines are conservative); the rotational
block is symmetric up to $\tfrac12 S(M)$, $M$ the moment of the loads on the held
body (a moment's derivative along a rotation is not that of a potential's
gradient), so it is symmetric where the held body's loads balance.

Every derivative is exact: the equilibrium carries the implicit-function theorem
(`jax.lax.custom_root`), and each catenary its own, so `jax.grad`, `jax.jacfwd`
and `jax.vmap` work through `mooring_equilibrium` and `coupled_stiffness` with
respect to any parameter: line lengths, EA, mass per length, anchor positions,
body properties, loads.

Not modelled: current drag on the lines (a catenary carries no distributed
horizontal load; use the lumped-mass `LineNetwork` for that: a `current` given
here is refused), a line hung between two points above the seabed that sags onto
it (MoorPy's "U" profile: reported, not solved), seabed contact of points and
bodies, line bending stiffness, rods.
"""

import math
import os
from functools import partial
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._arrays import BoolScalar, FloatScalar, IntScalar, f64, param as _param
from .._programs import eager_jit
from .._validate import (
    check_choice,
    check_int,
    check_nonnegative,
    check_positive,
    check_shape_finite,
    is_concrete,
    options_of,
    same_signature,
    show,
)
from .bodies import Body, euler_angles, rotation_from_vector, rotation_matrix
from .catenary import CatenarySolution, _forces as _catenary_forces


__all__ = [
    "MooringPoint",
    "MooringSystem",
    "MooringLoads",
    "MooringEquilibrium",
    "POINT_KINDS",
    "STATUS_MESSAGES",
    "mooring_system",
    "mooring_equilibrium",
    "coupled_stiffness",
]

POINT_KINDS = ("fixed", "coupled", "free", "body")

# MoorDyn's defaults (MoorDyn2.cpp): g, water density.
_G = 9.80665
_RHO = 1025.0

STATUS_MESSAGES = (
    "converged",
    "no equilibrium found within max_iter Newton iterations",
    "the line search found no step that lowers the residual: no equilibrium near "
    "this start (a load the lines cannot hold, or a direction nothing restrains)",
    "a line has no catenary at this pose (e.g. a fairlead below the seabed, which "
    "its anchor lies on)",
    "a line hangs below the seabed between two ends above it (a line that sags onto "
    "the seabed between its ends is not modelled)",
    "the loads or the system's parameters are not finite",
    "a line's catenary solve did not converge",
)


class MooringPoint(eqx.Module):
    """A point of a mooring system: an anchor, a fairlead, a clump weight, a buoy.

    **Arguments:**

    - `kind` (static): `"fixed"` (held), `"coupled"` (held at its position plus
      the coupled offsets), `"free"` (3 degrees of freedom), or `"body"` (fixed on
      body `body`).
    - `position`: m, shape (3,): global, or for `"body"` in the body's frame
      relative to its reference point.
    - `mass`: kg, $\\ge 0$ (a free point's or body point's weight $m g$).
    - `volume`: m^3, $\\ge 0$ (its buoyancy $\\rho_w g V$).
    - `body` (static): the index of the body in `MooringSystem.bodies` (only for
      `"body"`).
    - `name` (static): a label for messages.
    """

    kind: str = eqx.field(static=True)
    position: Float[Array, "3"] = _param()
    mass: FloatScalar = _param(default=0.0)
    volume: FloatScalar = _param(default=0.0)
    body: int = eqx.field(static=True, default=-1)
    name: str = eqx.field(static=True, default="point")

    def __check_init__(self):
        check_choice("point kind", self.kind, POINT_KINDS)
        check_shape_finite(f"position of {self.name}", self.position, (3,), "m")
        for field, unit in (("mass", "kg"), ("volume", "m^3")):
            check_shape_finite(
                f"{field} of {self.name}", getattr(self, field), (), unit
            )
            check_nonnegative(f"{field} of {self.name}", getattr(self, field), unit)
        if (self.kind == "body") != (self.body >= 0):
            raise ValueError(
                f"`body` of {self.name} must be the index (>= 0) of a body exactly "
                f"when its kind is 'body'; got kind {self.kind!r}, body {self.body!r}."
            )


class _Layout(NamedTuple):
    """Where each body and point sits in the free (x) and coupled (u) vectors."""

    body_free: tuple  # per body: start in x or -1
    body_coupled: tuple  # per body: start in u or -1
    point_free: tuple  # per point: start in x or -1
    point_coupled: tuple
    n_free: int
    n_coupled: int
    free_rot: tuple  # indices of x that are rotations
    coupled_rot: tuple


def _layout(bodies, points) -> _Layout:
    nf = nc = 0
    bf, bc, pf, pc, fr, cr = [], [], [], [], [], []
    for b in bodies:
        f = c = -1
        if b.kind == "free":
            f, nf = nf, nf + 6
            fr += [f + 3, f + 4, f + 5]
        elif b.kind == "pinned":
            f, nf = nf, nf + 3
            fr += [f, f + 1, f + 2]
            c, nc = nc, nc + 3
        elif b.kind == "coupled":
            c, nc = nc, nc + 6
            cr += [c + 3, c + 4, c + 5]
        bf.append(f)
        bc.append(c)
    for p in points:
        f = c = -1
        if p.kind == "free":
            f, nf = nf, nf + 3
        elif p.kind == "coupled":
            c, nc = nc, nc + 3
        pf.append(f)
        pc.append(c)
    return _Layout(
        tuple(bf), tuple(bc), tuple(pf), tuple(pc), nf, nc, tuple(fr), tuple(cr)
    )


class MooringSystem(eqx.Module):
    r"""Bodies, points and catenary lines between points, over a flat seabed.

    **Arguments:**

    - `bodies`: a tuple of `Body` (may be empty).
    - `points`: a tuple of `MooringPoint`.
    - `attach`: per line, the indices `(a, b)` of its end points in `points`
      (static). When one end is a fixed point on the seabed, the line's catenary
      is anchored there and the line can rest on the seabed; otherwise it hangs
      free between its ends.
    - `L`: unstretched lengths, m, shape (n_lines,), $> 0$.
    - `d`: volume-equivalent diameters, m, shape (n_lines,), $\ge 0$
      (buoyancy $\rho_w g \pi d^2/4$ per length).
    - `w`: mass per length, kg/m, shape (n_lines,), $> 0$.
    - `EA`: axial stiffness, N, shape (n_lines,), $> 0$.
    - `CB`: seabed friction coefficients, shape (n_lines,) or scalar, $\ge 0$
      (0: the laid length slides freely).
    - `depth`: water depth, m, $> 0$: the seabed lies at $z = -$depth (None: no
      seabed).
    - `g`: gravity, m/s^2 (MoorDyn's 9.80665; MoorPy's 9.81).
    - `rho`: water density, kg/m^3.
    - `hydrostatics`: per body, a linear hydrostatic stiffness, N/m, N/rad, N m/m,
      N m/rad, shape (n_bodies, 6, 6), or None (none).
    - `hydrostatic_pose`: the pose (position, m; roll, pitch, yaw, rad) about
      which each body's `hydrostatics` acts, shape (n_bodies, 6) (default: the
      bodies' given poses).
    - `line_ids`, `point_ids`, `body_ids` (static): labels (the deck's IDs).

    Fixed points must not lie below the seabed; a fixed point within
    $10^{-6}$ depth of it lies on it.
    """

    bodies: tuple
    points: tuple
    attach: tuple = eqx.field(static=True)
    L: Float[Array, " n"]
    d: Float[Array, " n"]
    w: Float[Array, " n"]
    EA: Float[Array, " n"]
    CB: Float[Array, " n"]
    depth: FloatScalar | None
    g: FloatScalar
    rho: FloatScalar
    hydrostatics: Float[Array, "b 6 6"] | None
    hydrostatic_pose: Float[Array, "b 6"] | None
    anchor_end: tuple = eqx.field(static=True)  # per line: 0 (A), 1 (B), -1 (none)
    line_ids: tuple = eqx.field(static=True)
    point_ids: tuple = eqx.field(static=True)
    body_ids: tuple = eqx.field(static=True)

    def __init__(
        self,
        bodies,
        points,
        attach,
        L,
        d,
        w,
        EA,
        CB=0.0,
        depth=None,
        g=_G,
        rho=_RHO,
        hydrostatics=None,
        hydrostatic_pose=None,
        line_ids=None,
        point_ids=None,
        body_ids=None,
    ):
        bodies, points = tuple(bodies), tuple(points)
        for i, b in enumerate(bodies):
            if not isinstance(b, Body):
                raise ValueError(
                    f"`bodies[{i}]` must be a Body; got {type(b).__name__}."
                )
        for i, p in enumerate(points):
            if not isinstance(p, MooringPoint):
                raise ValueError(
                    f"`points[{i}]` must be a MooringPoint; got {type(p).__name__}."
                )
            if p.kind == "body" and p.body >= len(bodies):
                raise ValueError(
                    f"`body` of {p.name} must be the index of one of the "
                    f"{len(bodies)} bodies (0 to {len(bodies) - 1}); got {p.body}."
                )
        try:
            attach = tuple((int(a), int(b)) for a, b in attach)
        except (TypeError, ValueError):
            raise ValueError(
                "`attach` must be pairs of point indices, one per line; got "
                f"{attach!r}."
            ) from None
        n = len(attach)
        if n == 0:
            raise ValueError("`attach` must list at least one line; got none.")
        for k, (a, b) in enumerate(attach):
            for end in (a, b):
                if not 0 <= end < len(points):
                    raise ValueError(
                        f"`attach[{k}]` = {(a, b)} must hold indices of points 0 to "
                        f"{len(points) - 1}."
                    )
            if a == b:
                raise ValueError(f"`attach[{k}]` joins point {a} to itself.")
        arrays = {}
        for name, v, unit in (
            ("L", L, "m"),
            ("d", d, "m"),
            ("w", w, "kg/m"),
            ("EA", EA, "N"),
            ("CB", CB, ""),
        ):
            v = f64(v)
            if v.ndim == 0:
                v = jnp.broadcast_to(v, (n,))
            check_shape_finite(name, v, (n,), unit)
            arrays[name] = v
        for name in ("L", "w", "EA"):
            check_positive(name, arrays[name], {"L": "m", "w": "kg/m", "EA": "N"}[name])
        check_nonnegative("d", arrays["d"], "m")
        check_nonnegative("CB", arrays["CB"])
        check_positive("g", g, "m/s^2")
        check_nonnegative("rho", rho, "kg/m^3")
        if depth is not None:
            check_positive("depth", depth, "m")
            depth = f64(depth)
        nb = len(bodies)
        if hydrostatics is not None:
            hydrostatics = f64(hydrostatics)
            check_shape_finite("hydrostatics", hydrostatics, (nb, 6, 6), "N/m, N m/rad")
            if hydrostatic_pose is None:
                hydrostatic_pose = jnp.stack(
                    [jnp.concatenate([b.position, b.rotation]) for b in bodies]
                ).reshape(nb, 6)
            hydrostatic_pose = f64(hydrostatic_pose)
            check_shape_finite("hydrostatic_pose", hydrostatic_pose, (nb, 6), "m, rad")
        elif hydrostatic_pose is not None:
            raise ValueError("`hydrostatic_pose` needs `hydrostatics`; got None.")
        # which end of each line is its anchor on the seabed (static)
        on_bed = []
        for i, p in enumerate(points):
            below = False
            on = False
            if p.kind == "fixed" and depth is not None and is_concrete(p.position):
                z, h = float(p.position[2]), float(depth)
                on = abs(z + h) <= 1e-6 * h
                below = z < -h and not on
            if below:
                raise ValueError(
                    f"{p.name} (fixed) lies below the seabed: z = {z:g} m < -depth = "
                    f"{-h:g} m; put it on the seabed (z = -depth) or above it."
                )
            on_bed.append(on)
        anchor_end = tuple(
            0 if on_bed[a] else 1 if on_bed[b] else -1 for a, b in attach
        )
        self.bodies = bodies
        self.points = points
        self.attach = attach
        self.L, self.d, self.w = arrays["L"], arrays["d"], arrays["w"]
        self.EA, self.CB = arrays["EA"], arrays["CB"]
        self.depth = depth
        self.g = f64(g)
        self.rho = f64(rho)
        self.hydrostatics = hydrostatics
        self.hydrostatic_pose = hydrostatic_pose
        self.anchor_end = anchor_end
        self.line_ids = (
            tuple(line_ids) if line_ids is not None else tuple(range(1, n + 1))
        )
        self.point_ids = (
            tuple(point_ids)
            if point_ids is not None
            else tuple(range(1, len(points) + 1))
        )
        self.body_ids = (
            tuple(body_ids) if body_ids is not None else tuple(range(1, nb + 1))
        )

    @property
    def n_lines(self) -> int:
        return len(self.attach)

    @property
    def layout(self) -> _Layout:
        """Where each body and point sits in the free and coupled vectors."""
        return _layout(self.bodies, self.points)

    @property
    def n_free(self) -> int:
        """Number of free degrees of freedom (6 per free body, 3 per pinned body and
        free point)."""
        return self.layout.n_free

    @property
    def n_coupled(self) -> int:
        """Number of coupled degrees of freedom (6 per coupled body, 3 per pinned
        body and coupled point): the size of `coupled_stiffness`."""
        return self.layout.n_coupled

    @property
    def submerged_weight(self) -> Float[Array, " n"]:
        r"""Each line's weight less buoyancy per length, $(w - \rho_w \pi d^2/4) g$,
        N/m."""
        return (self.w - self.rho * math.pi / 4.0 * self.d**2) * self.g

    def loads(self, body=None, point=None) -> "MooringLoads":
        """Steady loads on this system's bodies and points.

        **Arguments:** `body`: (n_bodies, 6) force, N, and moment about the
        reference point, N m, global axes, or a dict {body index: (6,)};
        `point`: (n_points, 3) force, N, or a dict {point index: (3,)}. Missing
        entries are zero.

        **Returns:** a `MooringLoads`.
        """
        nb, npt = len(self.bodies), len(self.points)
        return MooringLoads(
            body=_load_array("body", body, nb, 6),
            point=_load_array("point", point, npt, 3),
        )


def _load_array(name, value, n, k):
    if value is None:
        return np.zeros((n, k))
    if isinstance(value, dict):
        out = np.zeros((n, k))
        for i, v in value.items():
            if not isinstance(i, (int, np.integer)) or not 0 <= i < n:
                raise ValueError(
                    f"`{name}` loads: {i!r} must be an index from 0 to {n - 1}."
                )
            v = np.asarray(v, float)
            if v.shape != (k,):
                raise ValueError(
                    f"`{name}` loads: entry {i} must have shape ({k},); got {v.shape}."
                )
            out[i] = v
        return out
    return f64(value)


class MooringLoads(eqx.Module):
    """Steady loads on a mooring system (`MooringSystem.loads` builds them).

    **Fields:** `body`: force (N) and moment about the reference point (N m),
    global axes, shape (n_bodies, 6); `point`: force, N, shape (n_points, 3).
    Both are array leaves (differentiable).
    """

    body: Float[Array, "b 6"] = _param()
    point: Float[Array, "p 3"] = _param()


class MooringEquilibrium(eqx.Module):
    """The static equilibrium of a `MooringSystem` and the state of its solve.

    **Fields:**

    - `body_position` (n_bodies, 3), m; `body_rotation` (n_bodies, 3): roll,
      pitch, yaw, rad.
    - `point_position` (n_points, 3), m: every point, global (body points too).
    - `line_force` (n_lines, 2, 3), N: the force each line exerts on its end A
      and end B points.
    - `tension` (n_lines, 2), N: its magnitude at end A and end B.
    - `catenary`: the lines' `CatenarySolution`s (batched; `HF`, `VF` at the end
      away from the anchor, `LB` the length on the seabed).
    - `coupled_force` (n_coupled,): the net load on each coupled degree of freedom
      (lines, weight and buoyancy, hydrostatics, given loads), N and N m about the
      body's reference point: the body's support (a vessel) holds it with minus
      this.
    - `free` (n_free,): the solved free coordinates (displacements, m, and
      rotation vectors, rad, from the given pose).
    - `residual`: the largest net force (N) or moment divided by the system's
      length scale (N) on a free degree of freedom at the returned pose.
    - `force_scale`: the force the residual is measured against, N (the largest
      line tension or load).
    - `converged`: whether the residual is within `tol` of the force scale and
      every line is solved (`status` 0).
    - `status`: 0 converged, else the index of the reason in `STATUS_MESSAGES`.
    - `iterations`: Newton iterations taken.
    """

    body_position: Float[Array, "b 3"]
    body_rotation: Float[Array, "b 3"]
    point_position: Float[Array, "p 3"]
    line_force: Float[Array, "n 2 3"]
    tension: Float[Array, "n 2"]
    catenary: CatenarySolution
    coupled_force: Float[Array, " c"]
    free: Float[Array, " f"]
    residual: FloatScalar
    force_scale: FloatScalar
    converged: BoolScalar
    status: IntScalar
    iterations: IntScalar

    @property
    def message(self) -> str:
        """What `status` means (one text per member of a batch, joined)."""
        s = np.atleast_1d(np.asarray(self.status))
        return "; ".join(STATUS_MESSAGES[int(k)] for k in s)


# ---------------------------------------------------------------------------
# Forces


class _Pose(NamedTuple):
    r: Array  # (nb, 3) body reference points
    R: Array  # (nb, 3, 3) body rotations
    P: Array  # (np, 3) point positions


def _pose(system: MooringSystem, x, u) -> _Pose:
    lay = system.layout
    rs, Rs = [], []
    for i, b in enumerate(system.bodies):
        r, R = b.position, rotation_matrix(b.rotation)
        f, c = lay.body_free[i], lay.body_coupled[i]
        if b.kind == "free":
            r = r + x[f : f + 3]
            R = rotation_from_vector(x[f + 3 : f + 6]) @ R
        elif b.kind == "pinned":
            r = r + u[c : c + 3]
            R = rotation_from_vector(x[f : f + 3]) @ R
        elif b.kind == "coupled":
            r = r + u[c : c + 3]
            R = rotation_from_vector(u[c + 3 : c + 6]) @ R
        rs.append(r)
        Rs.append(R)
    r = jnp.stack(rs) if rs else jnp.zeros((0, 3))
    R = jnp.stack(Rs) if Rs else jnp.zeros((0, 3, 3))
    Ps = []
    for i, p in enumerate(system.points):
        pos = p.position
        if p.kind == "free":
            f = lay.point_free[i]
            pos = pos + x[f : f + 3]
        elif p.kind == "coupled":
            c = lay.point_coupled[i]
            pos = pos + u[c : c + 3]
        elif p.kind == "body":
            pos = r[p.body] + R[p.body] @ pos
        Ps.append(pos)
    return _Pose(r, R, jnp.stack(Ps))


def _line_forces(system: MooringSystem, P, tol, max_iter, given=None):
    """Forces on each line's end A and end B (n, 2, 3), and the catenaries.
    `given`: the lines' solved fairlead tensions (HF, VF) at these positions, shape
    (n, 2), to differentiate them without solving again."""
    ae = np.asarray(system.anchor_end)
    a_idx = np.array([a for a, _ in system.attach])
    b_idx = np.array([b for _, b in system.attach])
    flip = ae == 1  # the anchor is end B
    anc = np.where(flip, b_idx, a_idx)
    fair = np.where(flip, a_idx, b_idx)
    on = jnp.asarray(ae >= 0)
    W = system.submerged_weight

    def one(pa, pf, L, EA, W, CB, on, hv):
        return _catenary_forces(pa, pf, L, EA, W, CB, on, tol, max_iter, hv)

    hv = None if given is None else jnp.asarray(given)
    f_fair, f_anc, sol = jax.vmap(one)(
        P[anc], P[fair], system.L, system.EA, W, system.CB, on, hv
    )
    fl = jnp.asarray(flip)[:, None]
    fA = jnp.where(fl, f_fair, f_anc)
    fB = jnp.where(fl, f_anc, f_fair)
    return jnp.stack([fA, fB], axis=1), sol


def _length_scale(system: MooringSystem):
    """A length to turn moments into forces for the residual: the largest offset of
    a body point or centre of gravity from its body's reference point (>= 1 m)."""
    ls = jnp.asarray(1.0)
    for p in system.points:
        if p.kind == "body":
            ls = jnp.maximum(ls, jnp.linalg.norm(p.position))
    for b in system.bodies:
        ls = jnp.maximum(ls, jnp.linalg.norm(b.cg))
    return ls


class _Forces(NamedTuple):
    free: Array  # (n_free,)
    coupled: Array  # (n_coupled,)
    pose: _Pose
    line_force: Array  # (n, 2, 3)
    catenary: CatenarySolution


def _forces(
    system: MooringSystem, loads: MooringLoads, x, u, tol, max_iter, given=None
) -> _Forces:
    lay = system.layout
    pose = _pose(system, x, u)
    lf, sol = _line_forces(system, pose.P, tol, max_iter, given)
    g, rho = system.g, system.rho
    ez = jnp.array([0.0, 0.0, 1.0])
    # net force on each point: lines, weight and buoyancy, loads
    a_idx = jnp.asarray([a for a, _ in system.attach])
    b_idx = jnp.asarray([b for _, b in system.attach])
    mass = jnp.stack([p.mass for p in system.points])
    vol = jnp.stack([p.volume for p in system.points])
    fp = loads.point + ((rho * vol - mass) * g)[:, None] * ez
    fp = fp.at[a_idx].add(lf[:, 0]).at[b_idx].add(lf[:, 1])
    free_parts, coupled_parts = [], []
    for i, b in enumerate(system.bodies):
        if b.kind == "fixed":
            continue
        r, R = pose.r[i], pose.R[i]
        on = [
            k for k, p in enumerate(system.points) if p.kind == "body" and p.body == i
        ]
        F = loads.body[i, :3] + (rho * b.volume - b.mass) * g * ez
        M = loads.body[i, 3:] + jnp.cross(R @ b.cg, -b.mass * g * ez)
        if on:
            idx = jnp.asarray(on)
            F = F + jnp.sum(fp[idx], axis=0)
            M = M + jnp.sum(jnp.cross(pose.P[idx] - r, fp[idx]), axis=0)
        if system.hydrostatics is not None:
            q = jnp.concatenate([r, euler_angles(R)])
            fh = -system.hydrostatics[i] @ (q - system.hydrostatic_pose[i])
            F, M = F + fh[:3], M + fh[3:]
        f, c = lay.body_free[i], lay.body_coupled[i]
        if b.kind == "free":
            free_parts.append((f, jnp.concatenate([F, M])))
        elif b.kind == "pinned":
            free_parts.append((f, M))
            coupled_parts.append((c, F))
        else:
            coupled_parts.append((c, jnp.concatenate([F, M])))
    for k, p in enumerate(system.points):
        if p.kind == "free":
            free_parts.append((lay.point_free[k], fp[k]))
        elif p.kind == "coupled":
            coupled_parts.append((lay.point_coupled[k], fp[k]))
    Ff = _assemble(free_parts, lay.n_free)
    Fc = _assemble(coupled_parts, lay.n_coupled)
    return _Forces(Ff, Fc, pose, lf, sol)


def _assemble(parts, n):
    if n == 0:
        return jnp.zeros((0,))
    parts = sorted(parts, key=lambda p: p[0])
    return jnp.concatenate([v for _, v in parts])


def _residual_scale(system, n_free, ls):
    """Per free coordinate: 1 for a force row, 1/ls for a moment row."""
    rot = np.zeros(n_free, bool)
    rot[list(system.layout.free_rot)] = True
    return jnp.where(jnp.asarray(rot), 1.0 / ls, 1.0)


def _strong(tree):
    """Every floating array leaf as a float64 array of a fixed (not weak) type, so
    that parameters set from Python numbers (`eqx.tree_at(..., 2.0)`) reuse the
    compiled solve."""

    def strong(x):
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jnp.floating):
            if x.weak_type or x.dtype != jnp.float64:
                return x.astype(jnp.float64)
        return x

    return jax.tree_util.tree_map(strong, tree)


def _check_system(system):
    if not isinstance(system, MooringSystem):
        raise ValueError(
            f"`system` must be a MooringSystem (see mooring_system); got "
            f"{type(system).__name__}."
        )


def _check_loads(system, loads):
    if loads is None:
        return system.loads()
    if not isinstance(loads, MooringLoads):
        loads = system.loads(body=loads)
    nb, npt = len(system.bodies), len(system.points)
    check_shape_finite("loads.body", loads.body, (nb, 6), "N, N m")
    check_shape_finite("loads.point", loads.point, (npt, 3), "N")
    return loads


def _check_vector(name, value, n, unit):
    if value is None:
        return np.zeros((n,))
    value = f64(value)
    check_shape_finite(name, value, (n,), unit)
    return value


def _check_options(current, tol, max_iter, max_step):
    if current is not None:
        raise ValueError(
            f"`current` = {show(current)}: current drag on the lines is not modelled "
            "by the analytic catenaries (a catenary carries no distributed horizontal "
            "load); use None here, or the lumped-mass LineNetwork "
            "(jaxstring.lines.equilibrium) for lines in a current."
        )
    check_positive("tol", tol)
    check_int("max_iter", max_iter, 1)
    check_positive("max_step", max_step, "m")


def _checked(
    system, loads, offsets, guess, current, tol, max_iter, max_step, throw,
    stiffness=False,
):  # fmt: skip
    """The checked arguments of `mooring_equilibrium` (`stiffness` False) or
    `coupled_stiffness` (True): `(system, loads, offsets, guess)` as strongly
    typed arrays, and the solve's `_Cfg`."""
    _check_system(system)
    loads = _check_loads(system, loads)
    _check_options(current, tol, max_iter, max_step)
    if stiffness and system.n_coupled == 0:
        raise ValueError(
            "`system` has no coupled degree of freedom (no coupled or pinned body, no "
            "coupled point): its coupled stiffness is empty."
        )
    offsets = _check_vector("offsets", offsets, system.n_coupled, "m, rad")
    guess = _check_vector("guess", guess, system.n_free, "m, rad")
    cfg = _Cfg(
        float(tol), int(max_iter), float(max_step), 1e-12, stiffness, bool(throw)
    )
    return _strong((system, loads, offsets, guess)), cfg


def _moved(system: MooringSystem, u) -> MooringSystem:
    """The system with its coupled bodies and points moved by the offsets `u`
    (translations, and rotation vectors applied in global axes)."""
    lay = system.layout
    bodies = []
    for i, b in enumerate(system.bodies):
        c = lay.body_coupled[i]
        if b.kind == "coupled":
            R = rotation_from_vector(u[c + 3 : c + 6]) @ rotation_matrix(b.rotation)
            b = eqx.tree_at(
                lambda b: (b.position, b.rotation),
                b,
                (b.position + u[c : c + 3], euler_angles(R)),
            )
        elif b.kind == "pinned":
            b = eqx.tree_at(lambda b: b.position, b, b.position + u[c : c + 3])
        bodies.append(b)
    points = []
    for k, p in enumerate(system.points):
        if p.kind == "coupled":
            c = lay.point_coupled[k]
            p = eqx.tree_at(lambda p: p.position, p, p.position + u[c : c + 3])
        points.append(p)
    return eqx.tree_at(
        lambda s: (s.bodies, s.points), system, (tuple(bodies), tuple(points))
    )


def _base_scale(system, loads):
    """The force scale without the lines: the largest load and body weight or
    buoyancy, N (>= 1 N)."""
    fs = jnp.asarray(1.0)
    fs = jnp.maximum(fs, jnp.max(jnp.abs(loads.body), initial=0.0))
    fs = jnp.maximum(fs, jnp.max(jnp.abs(loads.point), initial=0.0))
    for b in system.bodies:
        fs = jnp.maximum(fs, system.g * jnp.maximum(b.mass, system.rho * b.volume))
    return jax.lax.stop_gradient(jnp.where(jnp.isfinite(fs), fs, 1.0))


# ---------------------------------------------------------------------------
# The solve and its derivatives


class _Cfg(NamedTuple):
    """The static settings of a solve."""

    tol: float
    max_iter: int
    max_step: float
    line_tol: float
    with_stiffness: bool
    throw: bool


def _outs(system, loads, x, u, line_tol, given=None) -> _Forces:
    """`_forces` with the catenaries' flags as floats (every output differentiable
    or carried as a float, so that one custom JVP covers them all). `given`: the
    lines' solved (HF, VF) at this pose (n, 2), to differentiate without solving
    the catenaries again."""
    F = _forces(system, loads, x, u, line_tol, 100, given)
    sol = F.catenary
    sol = eqx.tree_at(
        lambda s: (s.converged, s.iterations),
        sol,
        (sol.converged.astype(jnp.float64), sol.iterations.astype(jnp.float64)),
    )
    return F._replace(catenary=sol)


def _jac(fun, z):
    """Values and forward-mode Jacobians (leaf shape + (len(z),)) of every leaf of
    fun(z), in one pass."""

    def f(z):
        out = fun(z)
        return out, out

    return jax.jacfwd(f, has_aux=True)(z)[::-1]


def _newton(system, loads, guess, cfg: _Cfg):
    """Damped Newton on the free forces, one evaluation per loop turn (values and
    Jacobians of every output together, forward mode) at the trial point of a
    backtracking line search on the weighted residual norm: a trial that lowers it
    enough (Armijo) is accepted and gives the next Newton step, one that does not
    halves the step. Steps are limited to `max_step` (translations) and 0.3 rad
    (rotations). Returns the accepted point, its outputs and their Jacobians with
    respect to (x, u), the Newton iterations and the flag (0 converged,
    1 max_iter, 2 no descent)."""
    lay = system.layout
    nf, nc = lay.n_free, lay.n_coupled
    ncol = nf + (nc if cfg.with_stiffness else 0)
    weights = _residual_scale(system, nf, _length_scale(system))
    rot = np.zeros(nf, bool)
    rot[list(lay.free_rot)] = True
    rot = jnp.asarray(rot)
    base = _base_scale(system, loads)

    def evaluate(x):
        def fun(z):
            u = z[nf:] if cfg.with_stiffness else jnp.zeros((nc,))
            return _outs(system, loads, z[:nf], u, cfg.line_tol)

        z = jnp.concatenate([x, jnp.zeros((ncol - nf,))])
        return _jac(fun, z)

    def scale(out):
        t = jnp.max(jnp.abs(out.line_force))
        return jnp.maximum(base, jnp.where(jnp.isfinite(t), t, 0.0))

    def norm(r, fs):
        v = jnp.sqrt(jnp.sum((r * weights) ** 2)) / fs
        return jnp.where(jnp.isfinite(v), v, jnp.inf)

    # columns scaled like the rows (a rotation by the length scale), so that the
    # least-squares step below weighs forces and moments alike
    cols = 1.0 / weights

    def step(r, J):
        # The Newton step, in the least-squares sense: where the Jacobian is
        # singular (a slack or vertical line gives no stiffness across itself at
        # the start) the step leaves the unrestrained directions alone, rather
        # than failing.
        Js = weights[:, None] * J[:, :nf] * cols[None, :]
        ys, *_ = jnp.linalg.lstsq(Js, -r * weights, rcond=1e-13)
        dx = ys * cols
        ok = jnp.all(jnp.isfinite(dx))
        dx = jnp.where(ok, dx, 0.0)
        big_t = jnp.max(jnp.where(rot, 0.0, jnp.abs(dx)))
        big_r = jnp.max(jnp.where(rot, jnp.abs(dx), 0.0))
        a = jnp.minimum(cfg.max_step / jnp.maximum(big_t, 1e-300), 1.0)
        a = jnp.minimum(a, 0.3 / jnp.maximum(big_r, 1e-300))
        return dx, a, ok

    if nf == 0:
        out, jac = evaluate(guess)
        return guess, out, jac, jnp.asarray(0.0), jnp.asarray(0.0)

    def cond(c):
        return c["flag"] < 0

    def body(c):
        # the first turn evaluates the start (accepted as it is); later turns a
        # trial point
        first = c["evals"] == 0
        x_try = c["x"] + c["a"] * c["dx"]
        out, jac = evaluate(x_try)
        fs = jnp.where(first, scale(out), c["fs"])
        n_try = norm(out.free, fs)
        a = c["a"]
        accept = first | (n_try <= (1.0 - 1e-4 * a) * c["n"])
        pick = lambda new, old: jax.tree_util.tree_map(
            lambda p, q: jnp.where(accept, p, q), new, old
        )
        x = jnp.where(accept, x_try, c["x"])
        its = c["its"] + jnp.where(accept & ~first, 1, 0)
        dx_new, a_new, ok = step(out.free, jac.free)
        dx = jnp.where(accept, dx_new, c["dx"])
        a = jnp.where(accept, a_new, 0.5 * a)
        # converged against the force scale at the accepted point (the one the
        # returned status measures), not the start's: a start far from
        # equilibrium has larger tensions, and would stop Newton short of `tol`
        done = accept & (jnp.max(jnp.abs(out.free * weights)) <= cfg.tol * scale(out))
        stuck = (accept & ~ok) | (~accept & (a < 1e-12))
        flag = jnp.where(
            done, 0, jnp.where(stuck, 2, jnp.where(its >= cfg.max_iter, 1, -1))
        )
        return dict(x=x, out=pick(out, c["out"]), jac=pick(jac, c["jac"]),
                    n=jnp.where(accept, n_try, c["n"]), dx=dx, a=a, fs=fs,
                    its=its, evals=c["evals"] + 1, flag=flag)  # fmt: skip

    zeros = lambda t: jax.tree_util.tree_map(lambda v: jnp.zeros(v.shape, v.dtype), t)
    out0, jac0 = zeros(jax.eval_shape(evaluate, guess))
    init = dict(x=guess, out=out0, jac=jac0, n=jnp.asarray(jnp.inf),
                dx=jnp.zeros_like(guess), a=jnp.asarray(0.0), fs=jnp.asarray(1.0),
                its=jnp.asarray(0), evals=jnp.asarray(0),
                flag=jnp.asarray(-1))  # fmt: skip
    c = jax.lax.while_loop(cond, body, init)
    return (c["x"], c["out"], c["jac"], c["its"].astype(jnp.float64),
            c["flag"].astype(jnp.float64))  # fmt: skip


@partial(jax.custom_jvp, nondiff_argnums=(3,))
def _solved(system, loads, guess, cfg: _Cfg):
    """The equilibrium: free coordinates x, the outputs there, the Jacobian of the
    free and coupled forces with respect to (x, u) (with_stiffness; else w.r.t. x),
    and the Jacobians of every output w.r.t. those (private: their own derivative
    is not given), iterations, flag."""
    x, out, jac, its, flag = _newton(system, loads, guess, cfg)
    return x, out, _force_jacobian(jac), jac, its, flag


def _force_jacobian(jac):
    return jnp.concatenate([jac.free, jac.coupled], axis=0)


@_solved.defjvp
def _solved_jvp(cfg, primals, tangents):
    # The implicit-function theorem: F_f(x*(theta), theta) = 0 gives
    # dx = -J_ff^-1 (dF_f/dtheta . dtheta); every output moves by its partial
    # derivative along dtheta plus its Jacobian in x times dx.
    system, loads, guess = primals
    dsystem, dloads, _ = tangents
    x, out, G, jac, its, flag = _solved(system, loads, guess, cfg)
    lay = system.layout
    nf, nc = lay.n_free, lay.n_coupled
    u0 = jnp.zeros((nc,))

    # the lines as solved at the equilibrium: their derivatives come without a
    # new catenary solve
    hv = jnp.stack([out.catenary.HF, out.catenary.VF], axis=1)

    def outs(x, system, loads):
        return _outs(system, loads, x, u0, cfg.line_tol, hv)

    if nf:
        Jff = jac.free[:, :nf]
        if cfg.with_stiffness:
            # the free forces' change at the fixed pose (the outputs' come below)
            _, dF = jax.jvp(
                lambda s, lo: outs(x, s, lo).free, (system, loads), (dsystem, dloads)
            )
            dx = -jnp.linalg.solve(Jff, dF)
        else:
            _, d_theta = jax.jvp(
                lambda s, lo: outs(x, s, lo), (system, loads), (dsystem, dloads)
            )
            dx = -jnp.linalg.solve(Jff, d_theta.free)
            d_out = jax.tree_util.tree_map(
                lambda t, J: t + J[..., :nf] @ dx, d_theta, jac
            )
    else:
        dx = jnp.zeros((0,))
        if not cfg.with_stiffness:
            _, d_out = jax.jvp(outs, (x, system, loads), (dx, dsystem, dloads))
    if cfg.with_stiffness:
        # every output and the force Jacobian along (dx, dtheta), in one pass

        def outs_and_jacobian(x, system, loads):
            def G(z):
                F = _outs(system, loads, z[:nf], z[nf:], cfg.line_tol, hv)
                return jnp.concatenate([F.free, F.coupled]), F

            G, F = jax.jacfwd(G, has_aux=True)(jnp.concatenate([x, u0]))
            return F, G

        _, (d_out, dG) = jax.jvp(
            outs_and_jacobian, (x, system, loads), (dx, dsystem, dloads)
        )
    else:
        dG = jnp.zeros_like(G)
    zeros = jax.tree_util.tree_map(jnp.zeros_like, (jac, its, flag))
    return (x, out, G, jac, its, flag), (dx, d_out, dG, *zeros)


def _equilibrium_core(system, loads, offsets, guess, cfg: _Cfg):
    system = _moved(system, offsets)
    lay = system.layout
    nf = lay.n_free
    x, F, G, _, it, flag = _solved(system, loads, guess, cfg)
    it = jax.lax.stop_gradient(it).astype(jnp.int32)
    flag = jax.lax.stop_gradient(flag).astype(jnp.int32)
    sol = F.catenary
    sol = eqx.tree_at(
        lambda s: (s.converged, s.iterations),
        sol,
        (
            jax.lax.stop_gradient(sol.converged) > 0.5,
            jax.lax.stop_gradient(sol.iterations).astype(jnp.int32),
        ),
    )
    F = F._replace(catenary=sol)
    K = None
    if cfg.with_stiffness:
        # the Schur complement: the coupled forces' derivative along the
        # equilibrium of the free coordinates
        Jcc = G[nf:, nf:]
        if nf:
            Jcc = Jcc - G[nf:, :nf] @ jnp.linalg.solve(G[:nf, :nf], G[:nf, nf:])
        K = -Jcc
    weights = _residual_scale(system, nf, _length_scale(system))
    res = jax.lax.stop_gradient(jnp.max(jnp.abs(F.free * weights), initial=0.0))
    fscale = jnp.maximum(_base_scale(system, loads), jnp.max(jnp.abs(F.line_force)))
    fscale = jax.lax.stop_gradient(jnp.where(jnp.isfinite(fscale), fscale, 1.0))
    status = _status(system, loads, F, res, fscale, cfg.tol, flag)
    out = MooringEquilibrium(
        body_position=F.pose.r,
        body_rotation=jax.vmap(euler_angles)(F.pose.R) if system.bodies else F.pose.r,
        point_position=F.pose.P,
        line_force=F.line_force,
        tension=jnp.linalg.norm(F.line_force, axis=2),
        catenary=sol,
        coupled_force=F.coupled,
        free=x,
        residual=res,
        force_scale=fscale,
        converged=status == 0,
        status=status,
        iterations=it,
    )
    return out, K


@eager_jit(tiered=True)
def _equilibrium(system, loads, offsets, guess, cfg):
    out = _equilibrium_core(system, loads, offsets, guess, cfg)[0]
    return _throw(out) if cfg.throw else out


@eager_jit(tiered=True)
def _stiffness(system, loads, offsets, guess, cfg):
    out, K = _equilibrium_core(system, loads, offsets, guess, cfg)
    if cfg.throw:
        out = _throw(out)
        K = eqx.error_if(
            K, ~jnp.all(out.converged), "coupled_stiffness: no equilibrium"
        )
    return K, out


def _status(system, loads, F, res, fscale, tol, flag):
    """The outcome code (STATUS_MESSAGES) of a solve."""
    sol = F.catenary
    finite = jnp.all(jnp.isfinite(loads.body)) & jnp.all(jnp.isfinite(loads.point))
    for leaf in jax.tree_util.tree_leaves(eqx.filter(system, eqx.is_inexact_array)):
        finite = finite & jnp.all(jnp.isfinite(leaf))
    no_line = ~jnp.all(jnp.isfinite(sol.HF) & jnp.isfinite(sol.VF))
    line_fail = ~jnp.all(sol.converged)
    below = _below_seabed(system, F)
    ok = (res <= tol * fscale) & jnp.isfinite(res)
    status = jnp.where(ok, 0, jnp.where(flag == 0, 1, flag))
    status = jnp.where(line_fail, 6, status)
    status = jnp.where(below, 4, status)
    status = jnp.where(no_line, 3, status)
    status = jnp.where(finite, status, 5)
    return status.astype(jnp.int32)


def _below_seabed(system, F):
    """Whether a line whose ends both lie above the seabed dips below it."""
    if system.depth is None:
        return jnp.asarray(False)
    free_lines = np.asarray(system.anchor_end) < 0
    if not free_lines.any():
        return jnp.asarray(False)
    sol = F.catenary
    W = system.submerged_weight
    pa = F.pose.P[jnp.asarray([a for a, _ in system.attach])]
    pb = F.pose.P[jnp.asarray([b for _, b in system.attach])]
    # lowest point inside the span, where the vertical tension changes sign
    # (VA < 0 < VF, W > 0): (HF - TA)/W + (VA u + W u^2/2)/EA below... above end A
    inside = (sol.VA < 0) & (sol.VF > 0) & (W > 0)
    Ws = jnp.where(inside, W, 1.0)
    u = -sol.VA / Ws
    TA = jnp.sqrt(sol.HF**2 + sol.VA**2)
    dz = (sol.HF - TA) / Ws + (sol.VA * u + 0.5 * Ws * u * u) / system.EA
    z_low = jnp.minimum(pa[:, 2], pb[:, 2])
    z_low = jnp.where(inside, jnp.minimum(z_low, pa[:, 2] + dz), z_low)
    tol = 1e-6 * system.depth
    return jnp.any(jnp.asarray(free_lines) & (z_low < -system.depth - tol))


def mooring_equilibrium(
    system: MooringSystem,
    loads=None,
    *,
    offsets=None,
    guess=None,
    current=None,
    tol: float = 1e-10,
    max_iter: int = 100,
    max_step: float = 20.0,
    throw: bool = True,
) -> MooringEquilibrium:
    r"""Find the static equilibrium of a mooring system under steady loads.

    Newton's method on the net forces and moments of the free degrees of freedom
    (module docstring), with the Jacobian by forward-mode automatic
    differentiation (each catenary's exact derivative) and a backtracking line
    search; steps are limited to `max_step` (translations) and 0.3 rad
    (rotations). The pose is an equilibrium when the largest residual force (a
    moment divided by the system's length scale) is within `tol` of the force
    scale (the largest line tension or load). Derivatives of every output with
    respect to the system's parameters, the loads and the offsets are exact
    (implicit-function theorem).

    **Arguments:**

    - `system`: a `MooringSystem`.
    - `loads`: a `MooringLoads`, or an array (n_bodies, 6) of body loads (force,
      N; moment about the reference point, N m; global axes), or None (none).
    - `offsets`: displacements of the coupled degrees of freedom from their given
      pose, shape (n_coupled,): per coupled body 3 translations, m, and 3 small
      rotations about the global axes (a rotation vector), rad; per pinned body
      and coupled point 3 translations (default zero).
    - `guess`: the free coordinates to start from, shape (n_free,) (default zero:
      the given pose).
    - `current`: not supported (a ValueError says why), kept so that the refusal
      is explicit.
    - `tol`: residual relative to the force scale at convergence.
    - `max_iter`: most Newton iterations. `max_step`: longest step, m.
    - `throw`: raise when the solve fails (an `EquinoxRuntimeError` carrying the
      message; inside `jax.vmap` when any member fails). With `throw=False` check
      `converged` and `status`.

    **Returns:** a `MooringEquilibrium`.

    **Raises:** `ValueError` for bad input (before anything compiles), naming the
    argument, its value and the valid range.
    """
    args, cfg = _checked(
        system, loads, offsets, guess, current, tol, max_iter, max_step, throw
    )
    return _equilibrium(*args, cfg)


def _throw(out):
    st = out.status
    return eqx.tree_at(
        lambda o: o.tension,
        out,
        eqx.branched_error_if(
            out.tension,
            jnp.any(st != 0),
            jnp.max(st),
            [f"mooring_equilibrium: {m}" for m in STATUS_MESSAGES],
        ),
    )


def coupled_stiffness(system: MooringSystem, loads=None, **options):
    r"""Compute the stiffness of the coupled degrees of freedom, free ones re-balanced.

    At the equilibrium of the free degrees of freedom (`mooring_equilibrium`),
    $K = -\,dF_c/du$ along the equilibrium: $K = -(J_{cc} - J_{cf} J_{ff}^{-1}
    J_{fc})$ with $J = \partial(F_f, F_c)/\partial(x, u)$ (exact, by automatic
    differentiation of the catenaries; MoorPy's `getCoupledStiffness` takes the
    same by finite differences). Columns: per coupled body 3 translations and 3
    small rotations about the global axes at the pose, per pinned body and
    coupled point 3 translations; rows: the matching forces, N, and moments about
    the reference point, N m. Derivatives of `K` with respect to every parameter
    are exact too.

    **Arguments:** `system`, `loads` and the keyword options of
    `mooring_equilibrium` (`offsets`, `guess`, `current`, `tol`, `max_iter`,
    `max_step`, `throw`).

    **Returns:** `(K, equilibrium)`: `K` of shape (n_coupled, n_coupled) in N/m,
    N/rad, N m/m, N m/rad, and the `MooringEquilibrium`.
    """
    options = options_of(mooring_equilibrium, "coupled_stiffness", options, skip=2)
    args, cfg = _checked(system, loads, stiffness=True, **options)
    return _stiffness(*args, cfg)


same_signature(coupled_stiffness, mooring_equilibrium, skip=2)


# ---------------------------------------------------------------------------
# From a MoorDyn deck


def mooring_system(
    deck,
    *,
    vessel: Body | None = None,
    g=None,
    rho=None,
    depth=None,
    CB=0.0,
    hydrostatics=None,
    hydrostatic_pose=None,
) -> MooringSystem:
    """Build the catenary `MooringSystem` of a MoorDyn v2 deck.

    Points keep their kinds (Fixed/Anchor: fixed; Vessel/Coupled/Fairlead:
    coupled; Free/Connect: free, with their mass and volume); each line becomes a
    catenary of its type's diameter, mass per length and EA (the number of
    segments, the damping and the drag coefficients play no part in the statics).

    **Arguments:**

    - `deck`: a `MoorDynDeck` (`parse_moordyn`) or the path of a deck.
    - `vessel`: a `Body` that carries the deck's coupled points: they become
      points fixed on it, at their deck positions (so that the body's pose moves
      them all; e.g. a coupled or free spar at the fairleads' centre). None:
      coupled points stay coupled points.
    - `g`, `rho`, `depth`: override the deck's gravity (m/s^2), water density
      (kg/m^3) and depth (m); e.g. `g=9.81` to compare with MoorPy.
    - `CB`: seabed friction coefficient of every line (default 0: free sliding).
    - `hydrostatics`, `hydrostatic_pose`: of the vessel, shape (6, 6) and (6,)
      (see `MooringSystem`).

    **Returns:** a `MooringSystem` (line, point and body IDs as in the deck).
    """
    from .moordyn import MoorDynDeck, parse_moordyn

    if isinstance(deck, (str, os.PathLike)):
        deck = parse_moordyn(deck)
    if not isinstance(deck, MoorDynDeck):
        raise ValueError(
            f"`deck` must be a MoorDynDeck or a path; got {type(deck).__name__}."
        )
    if vessel is not None and not isinstance(vessel, Body):
        raise ValueError(f"`vessel` must be a Body; got {type(vessel).__name__}.")
    o = deck.options
    points, index = [], {}
    R0 = None if vessel is None else np.asarray(rotation_matrix(vessel.rotation))
    for p in deck.points:
        index[p["id"]] = len(points)
        pos = np.asarray(p["position"], float)
        name = f"point {p['id']}"
        if p["kind"] == "coupled" and vessel is not None:
            rel = R0.T @ (pos - np.asarray(vessel.position))
            points.append(MooringPoint("body", rel, body=0, name=name))
        elif p["kind"] == "free":
            points.append(MooringPoint("free", pos, p["mass"], p["volume"], name=name))
        else:
            points.append(MooringPoint(p["kind"], pos, name=name))
    types = [deck.types[ln["type"]] for ln in deck.lines]
    dpt = o["depth"] if depth is None else depth
    hs = hp = None
    if hydrostatics is not None:
        if vessel is None:
            raise ValueError("`hydrostatics` needs a `vessel`; got vessel=None.")
        hs = f64(hydrostatics)[None]
        hp = None if hydrostatic_pose is None else f64(hydrostatic_pose)[None]
    return MooringSystem(
        bodies=() if vessel is None else (vessel,),
        points=tuple(points),
        attach=tuple((index[ln["a"]], index[ln["b"]]) for ln in deck.lines),
        L=[ln["L"] for ln in deck.lines],
        d=[t["d"] for t in types],
        w=[t["w"] for t in types],
        EA=[t["EA"] for t in types],
        CB=CB,
        depth=dpt if dpt > 0 else None,
        g=o["g"] if g is None else g,
        rho=o["rho"] if rho is None else rho,
        hydrostatics=hs,
        hydrostatic_pose=hp,
        line_ids=tuple(ln["id"] for ln in deck.lines),
        point_ids=tuple(p["id"] for p in deck.points),
        body_ids=() if vessel is None else (1,),
    )
