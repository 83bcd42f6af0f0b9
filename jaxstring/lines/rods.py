"""Rods: rigid cylinders that lines attach to (MoorDyn v2's Rod).

A rod runs from end A to end B (length L = |B - A|, N segments, N + 1 nodes
evenly spaced along its axis q = (B - A)/L). It is rigid: no bending, no axial
strain. How it is held (`kind`):

- `"fixed"`: fixed in space (or, with `body`, fixed to a body);
- `"pinned"`: end A fixed (or on a body), free to rotate about it;
- `"free"`: six degrees of freedom;
- `"coupled"`, `"coupled_pinned"`: moved by a prescribed motion (all six degrees
  of freedom, or end A only).

A line end on a rod end is clamped to the rod's axis where the line has bending
stiffness (`jaxstring.lines.bending`): a fixed rod is the clamp of a cantilever.
"""

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._arrays import FloatScalar, param as _param
from .._geometry import safe_norm
from .._validate import check_choice, check_finite, check_nonnegative, check_shape
from .rigid import RigidMotion


class RodEnd(NamedTuple):
    """A line end on a rod end: `rod` (index in `LineNetwork.rods`), `end` ("A" or
    "B")."""

    rod: int
    end: str


ROD_KINDS = ("fixed", "pinned", "free", "coupled", "coupled_pinned")


class Rod(eqx.Module):
    """A rigid cylinder (see the module docstring).

    **Arguments:**

    - `end_a`, `end_b`: the ends, `(3,)`, m: in the earth frame, or in the body's
      frame (relative to its reference point) when `body` is given.
    - `segments`: N >= 0 (structure; 0 is a zero-length joint).
    - `d` (diameter, m), `w` (mass per length, kg/m), `Cd` (transverse drag on
      d l), `Ca` (transverse added mass on the displaced volume), `CdEnd` (axial
      drag on each submerged end's area pi d^2/4), `CaEnd` (axial added mass on
      each submerged end's half sphere pi d^3/12): scalars >= 0.
    - `kind`: one of "fixed", "pinned", "free", "coupled", "coupled_pinned"
      (structure).
    - `body`: index of the body it is fixed or pinned to (structure; None: the
      earth).
    - `motion`: for a "coupled" rod, the `RigidMotion` of its frame (origin end A,
      turning its axis); for "coupled_pinned", of end A (the rotations are not
      used). None: held at its initial pose.
    """

    end_a: Float[Array, "3"] = _param()
    end_b: Float[Array, "3"] = _param()
    segments: int = eqx.field(static=True)
    d: FloatScalar = _param()
    w: FloatScalar = _param()
    Cd: FloatScalar = _param(default=0.0)
    Ca: FloatScalar = _param(default=0.0)
    CdEnd: FloatScalar = _param(default=0.0)
    CaEnd: FloatScalar = _param(default=0.0)
    kind: str = eqx.field(static=True, default="fixed")
    body: int | None = eqx.field(static=True, default=None)
    motion: RigidMotion | None = None

    kinds: ClassVar[tuple[str, ...]] = ROD_KINDS

    def __check_init__(self):
        for name in ("end_a", "end_b"):
            check_shape(name, getattr(self, name), (3,), "m")
            check_finite(name, getattr(self, name))
        if (
            isinstance(self.segments, bool)
            or not isinstance(self.segments, int)
            or self.segments < 0
        ):
            raise ValueError(
                f"`segments` must be an integer >= 0; got {self.segments!r}."
            )
        for name, unit in (("d", "m"), ("w", "kg/m")):
            check_shape(name, getattr(self, name), (), unit)
            check_nonnegative(name, getattr(self, name), unit)
        for name in ("Cd", "Ca", "CdEnd", "CaEnd"):
            check_shape(name, getattr(self, name), ())
            check_nonnegative(name, getattr(self, name))
        check_choice("kind", self.kind, ROD_KINDS)
        if self.motion is not None and not isinstance(self.motion, RigidMotion):
            raise ValueError(
                f"`motion` must be a RigidMotion or None; got {self.motion!r}."
            )
        if self.motion is not None and self.kind not in ("coupled", "coupled_pinned"):
            raise ValueError(
                f"`motion` is for a 'coupled' or 'coupled_pinned' rod; this rod is "
                f"{self.kind!r}."
            )
        if self.body is not None and self.kind not in ("fixed", "pinned"):
            raise ValueError(
                f"`kind` must be 'fixed' or 'pinned' for a rod on a body; got "
                f"{self.kind!r}."
            )

    @property
    def length(self):
        """Length |B - A|, m (0 for a zero-length rod)."""
        if self.segments == 0:
            return jnp.zeros(())
        return jnp.linalg.norm(self.end_b - self.end_a)

    def axis(self):
        """Unit axis from A to B (for a zero-length rod, end B is the direction)."""
        v = self.end_b if self.segments == 0 else self.end_b - self.end_a
        return v / jnp.linalg.norm(v)


class RodLoads(eqx.Module):
    """What `rod_loads` computes for one rod (N + 1 nodes)."""

    positions: Array  # (N + 1, 3) node positions, m
    velocities: Array  # (N + 1, 3)
    forces: Array  # (N + 1, 3) node forces, N
    masses: Array  # (N + 1, 3, 3) node mass matrices incl. added mass, kg
    moment: Array  # (3,) pure moment on the rod (end caps, waterplane), N m
    inertia: Array  # (3, 3) rotational inertia beyond the lumped nodes, kg m^2
    submerged: Array  # (N + 1,) volume fraction of each node under water


def rod_loads(rod: Rod, end_a, axis, vel_a, omega, t, env, loads):
    """MoorDyn's rod loads (Rod.cpp `doRHS`, still water or a current) at a pose.

    The rod's nodes lie at r_i = A + (i/N) L q, moving at v_A + (i/N) omega x L q.
    Per node (length dL = l/2 at the ends, l = L/N inside; volume v_i = A dL):

    - weight -m_i g e_z (`"gravity"` in `loads`);
    - side buoyancy VOF_i rho g v_i (e_z - (e_z . q) q), the buoyancy normal to the
      axis; each submerged end cap the pressure -+ VOF rho g A z_A q of the depth
      z_A of its wetted centroid and the moment -+ VOF rho g (pi d^4/64) q x e_z,
      and the waterplane moment (pi d^4/16) rho g (q . e_z) q x e_z of a rod
      through the surface (`"buoyancy"`);
    - transverse drag 1/2 rho Cd d dL VOF |u_p| u_p on the velocity relative to the
      water, and the axial drag 1/2 rho CdEnd A VOF |u_q| u_q on each end
      (`"drag"`, times the `Drag` effect's `scale`);
    - mass m_i I plus the added mass VOF rho v_i Ca (I - q q^T), and
      VOF rho CaEnd (pi d^3/12) q q^T on each end.

    VOF_i, the node's submerged fraction, blends the length of the rod under the
    surface z = 0 (axial) and the wetted part of its cross-section (transverse) by
    the rod's inclination (Rod.cpp). The lumped nodes' rotational inertia about
    end A is corrected to a solid cylinder's by `inertia`,
    m ((d/2)^2/4 - L^2/(6 N^2)) (I - q q^T) + m (d/2)^2/2 q q^T.

    **Arguments:** the rod; end A's position `end_a`, unit `axis`, end A's
    velocity `vel_a` and the angular velocity `omega` (each `(3,)`); time `t`;
    the `Environment`; `loads`: a dict of the scene's loads that apply,
    `"gravity"`, `"buoyancy"`, `"drag"` (the `Drag` effect), `"seabed"` (the
    `Seabed` effect), absent keys traced as absent.
    """
    N = rod.segments
    L = jnp.linalg.norm(rod.end_b - rod.end_a)
    q = axis
    s = jnp.linspace(0.0, 1.0, N + 1)
    r = end_a + s[:, None] * (L * q)
    v = vel_a + s[:, None] * jnp.cross(omega, L * q)
    d = rod.d
    area = 0.25 * jnp.pi * d**2
    l = L / N
    inner = np.ones(N + 1)
    inner[0] = inner[-1] = 0.5
    dL = l * inner
    vol = area * dL
    m = rod.w * dL
    eye = jnp.eye(3)
    Q = jnp.outer(q, q)
    rho, g = env.rho_water, env.g
    z = r[:, 2]
    # the submerged length h0 from end A (negative: measured from B, rod upside down)
    zA, zB = z[0], z[-1]
    qz = jnp.where(jnp.abs(q[2]) > 0, q[2], 1.0)
    h0 = jnp.where(
        (zA < 0) & (zB < 0),
        L,
        jnp.where((zA < 0) & (zB > 0), -zA / qz,
                  jnp.where((zB < 0) & (zA > 0), zA / qz, 0.0)),
    )  # fmt: skip
    before = jnp.concatenate([jnp.zeros(1), jnp.cumsum(dL)[:-1]])
    up = jnp.where(
        before + dL <= h0, 1.0, jnp.where(before < h0, (h0 - before) / dL, 0.0)
    )
    down = jnp.where(
        before >= -h0,
        1.0,
        jnp.where(before + dL > -h0, (before + dL + h0) / dL, 0.0),
    )
    vof0 = jnp.where(h0 >= 0, up, down)
    # the wetted part of each node's cross-section
    sin_phi = safe_norm(q[:2])
    cos_phi = q[2]
    half = 0.5 * d * sin_phi
    lo, hi = z - half, z + half
    sp = jnp.where(sin_phi > 0, sin_phi, 1.0)
    G = jnp.clip(z / sp / (0.5 * d), -1.0, 1.0)
    alpha = jnp.arccos(G)
    seg = 2 * alpha - jnp.sin(2 * alpha)
    seg_safe = jnp.where(seg > 0, seg, 1.0)
    crossing = jnp.where(
        sin_phi < 0.001, 0.5, d**2 / 8 * seg
    )  # MoorDyn's literal 0.5 m^2 for a level rod through the surface
    crossing_z = jnp.where(
        sin_phi < 0.001, 0.0, z - 2.0 / 3.0 * d * jnp.sin(alpha) ** 3 / seg_safe
    )
    wet = jnp.where(lo > 0, 0.0, jnp.where(hi < 0, area, crossing))
    wet_z = jnp.where(lo > 0, 0.0, jnp.where(hi < 0, z, crossing_z))
    vof = vof0 * cos_phi**2 + wet / area * sin_phi**2
    # masses
    mass = m[:, None, None] * eye + (vof * rho * vol * rod.Ca)[:, None, None] * (
        eye - Q
    )
    cap = 0.5 * jnp.pi * d**3 / 6.0  # a half sphere, pi d^3 / 12
    ends = np.zeros(N + 1)
    ends[0] = ends[-1] = 1.0
    # only ends whose lowest point is under water
    end_wet = jnp.where(lo < 0, ends, 0.0) * vof
    mass = mass + (end_wet * rho * rod.CaEnd * cap)[:, None, None] * Q
    f = jnp.zeros_like(r)
    moment = jnp.zeros(3)
    ez = jnp.array([0.0, 0.0, 1.0])
    qxz = jnp.cross(q, ez)
    if "gravity" in loads:
        f = f - (m * g)[:, None] * ez
    if "buoyancy" in loads:
        f = f + (vof * vol * rho * g)[:, None] * (ez - cos_phi * q)
        sign = np.zeros(N + 1)
        sign[0], sign[-1] = -1.0, 1.0
        f = f + (sign * end_wet * area * rho * g * wet_z)[:, None] * q
        cap_moment = jnp.pi * d**4 / 64 * rho * g
        moment = moment + jnp.sum(sign * end_wet) * cap_moment * qxz
        through = (zA < 0) & (zB > 0)
        plane = jnp.where(through, jnp.pi * d**4 / 16 * rho * g * cos_phi, 0.0)
        moment = moment + plane * qxz
    if "drag" in loads:
        u = -v
        if env.current is not None:
            u = u + env.current(t, r)
        uq = (u @ q)[:, None] * q
        up = u - uq
        scale = loads["drag"].scale
        f = f + scale * (0.5 * rho * rod.Cd * d * dL * vof)[:, None] * (
            safe_norm(up, keepdims=True) * up
        )
        f = f + scale * (0.5 * rho * rod.CdEnd * area * end_wet)[:, None] * (
            safe_norm(uq, keepdims=True) * uq
        )
    if "seabed" in loads:
        # vertical contact only (MoorDyn's rods feel no seabed friction), its edge
        # smoothed over eps with an exponential tail (exactly MoorDyn's law a few
        # eps away from the seabed)
        bed = loads["seabed"]
        delta = (-bed.depth - z) / bed.eps
        pen = bed.eps * jax.nn.softplus(delta)
        fz = (bed.kBot * pen - bed.cBot * v[:, 2] * jax.nn.sigmoid(delta)) * d * dL
        f = f + fz[:, None] * ez
    total = rod.w * L
    a2 = (0.5 * d) ** 2
    Irc = total * (a2 / 4 - L**2 / (6 * N**2))
    inertia = Irc * (eye - Q) + total * a2 / 2 * Q
    return RodLoads(r, v, f, mass, moment, inertia, vof)
