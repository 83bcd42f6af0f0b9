"""Loads on a mooring-line network: weight and buoyancy, Morison drag in a current,
and seabed contact with regularised friction.

Every effect here is an ``AbstractLineLoad`` (the one protocol of
``jaxstring.AbstractLoad``): ``forces(t, kin, env)`` maps the kinematics of the line
nodes and the free points (`LineKinematics`) and the scene's ``Environment`` (g, water
density, current) to `LineForces`: one force per line node and one per free point,
in the earth frame (x, y horizontal, z up, the still-water surface at z = 0). The
lumped-mass conventions are MoorDyn's (v2): node i of a line stands for half of each
adjacent segment's unstretched length, its mass is w l_i and its submerged volume
A l_i times the submerged fraction of those segments; the node's axis q_i is the
direction from node i - 1 to node i + 1 (the segment's direction at the ends).

Added mass is part of the model's mass matrix (line-type Ca, CaAx and point Ca), not
an effect: it changes the inertia that the accelerations divide by.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._effect import AbstractLoad
from .._geometry import safe_norm
from .._validate import check_choice, check_nonnegative, check_shape


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


class LineKinematics(eqx.Module):
    """Kinematics and per-node properties handed to the line loads.

    **Fields** (M line nodes, every node of every line, ends included; P free points):

    - `positions`, `velocities`: `(M, 3)`, m and m/s.
    - `tangents`: unit node axes q_i, `(M, 3)`.
    - `mass`: lumped node mass w l_i, `(M,)`, kg.
    - `volume`: submerged node volume, `(M,)`, m^3.
    - `length`: unstretched length the node stands for, l_i, `(M,)`, m.
    - `submerged_length`: its submerged part, `(M,)`, m.
    - `diameter`, `Cd`, `CdAx`: of the node's line type, `(M,)` (m, -, -).
    - `point_positions`, `point_velocities`: free points, `(P, 3)`.
    - `point_mass` (kg), `point_volume` (m^3), `point_CdA` (m^2): `(P,)`.
    """

    positions: Float[Array, "M 3"]
    velocities: Float[Array, "M 3"]
    tangents: Float[Array, "M 3"]
    mass: Float[Array, " M"]
    volume: Float[Array, " M"]
    length: Float[Array, " M"]
    submerged_length: Float[Array, " M"]
    diameter: Float[Array, " M"]
    Cd: Float[Array, " M"]
    CdAx: Float[Array, " M"]
    point_positions: Float[Array, "P 3"]
    point_velocities: Float[Array, "P 3"]
    point_mass: Float[Array, " P"]
    point_volume: Float[Array, " P"]
    point_CdA: Float[Array, " P"]


class LineForces(eqx.Module):
    """Forces of one load: `nodes` `(M, 3)` on the line nodes, `points` `(P, 3)` on
    the free points, N."""

    nodes: Float[Array, "M 3"]
    points: Float[Array, "P 3"]


class AbstractLineLoad(AbstractLoad):
    """A load on the nodes and free points of a line network.

    `constant`: True when the force depends on neither the state nor time."""

    constant: ClassVar[bool] = False

    @abc.abstractmethod
    def forces(self, t, kin: LineKinematics, env) -> LineForces:
        """Forces at time `t` (s) on the line nodes and the free points, N."""


def _up(x):
    return jnp.zeros_like(x).at[..., 2].set(1.0)


class Gravity(AbstractLineLoad):
    """Weight minus buoyancy: F_z = -g (m - rho V) on every line node (its
    submerged volume) and every free point (its volume), g and rho from the
    scene's `Environment`."""

    def forces(self, t, kin, env):
        del t
        net = kin.mass - env.rho_water * kin.volume
        pnet = kin.point_mass - env.rho_water * kin.point_volume
        return LineForces(
            nodes=-env.g * net[:, None] * _up(kin.positions),
            points=-env.g * pnet[:, None] * _up(kin.point_positions),
        )


class Drag(AbstractLineLoad):
    """Quadratic (Morison) drag on the velocity relative to the current.

    With the relative water velocity u = v_c(p, t) - v split along the node axis q
    (u_q = (u . q) q) and across it (u_p = u - u_q), a line node gets

        F = 1/2 rho d l_s (Cd |u_p| u_p + pi CdAx |u_q| u_q),

    l_s the node's submerged length (MoorDyn's normal drag on the projected area
    d l_s and axial drag on the wetted surface pi d l_s); a free point gets
    1/2 rho CdA |u| u. The norms go through a double-where, so the force and its
    gradient are finite (zero) at zero relative velocity. The current is the
    scene's `Environment.current` (still water without one).

    The axial coefficient's reference area differs between codes: MoorDyn
    applies CdAx to the wetted surface pi d l_s, while DNV-OS-E301's chain
    coefficients (studless: 2.4 normal, 1.15 axial, on the bar diameter) and
    OrcaFlex's chain line type (axial drag diameter d/pi) apply it to d l_s.
    A deck whose CdAx was converted from those values (1.15 / 1.8 = 0.64 on the
    1.8 d volumetric diameter) gets pi times their axial drag in MoorDyn.

    **Arguments:**

    - `scale`: a factor on every drag coefficient (default 1; MoorDyn's CdScaleIC
      uses > 1 to damp a relaxation).
    - `axial_area`: the reference area of CdAx per unit length: `"surface"`
      (pi d, MoorDyn's, default) or `"diameter"` (d, DNV-OS-E301 and OrcaFlex's
      chain).
    """

    scale: Float[Array, ""] = eqx.field(converter=_f64, default=1.0)
    axial_area: str = eqx.field(static=True, default="surface")

    def __check_init__(self):
        check_shape("scale", self.scale, ())
        check_nonnegative("scale", self.scale)
        check_choice("axial_area", self.axial_area, ("surface", "diameter"))

    @property
    def _axial_factor(self):
        return jnp.pi if self.axial_area == "surface" else 1.0

    def forces(self, t, kin, env):
        u = env.water_velocity(t, kin.positions) - kin.velocities
        q = kin.tangents
        uq = jnp.sum(u * q, axis=-1, keepdims=True) * q
        up = u - uq
        half = 0.5 * env.rho_water * kin.diameter * kin.submerged_length
        f = half[:, None] * (
            kin.Cd[:, None] * safe_norm(up, keepdims=True) * up
            + self._axial_factor * kin.CdAx[:, None] * safe_norm(uq, keepdims=True) * uq
        )
        pu = env.water_velocity(t, kin.point_positions) - kin.point_velocities
        fp = (0.5 * env.rho_water * kin.point_CdA)[:, None] * (
            safe_norm(pu, keepdims=True) * pu
        )
        return LineForces(nodes=self.scale * f, points=self.scale * fp)


class Seabed(AbstractLineLoad):
    """A flat seabed at z = -`depth`: MoorDyn's contact law with smooth edges.

    A line node at penetration delta = -depth - z > 0 gets the vertical force
    F_z = (kBot delta - cBot v_z) d l_i (kBot in Pa/m, cBot in Pa s/m, per unit of
    the node's projected area d l_i), and a friction force against its horizontal
    velocity v_h that grows linearly, mu FricDamp |v_h|, and saturates at
    mu |F_z| (MoorDyn's FricDamp = 200 N s/m, StatDynFricScale = 1). Here both
    edges are smooth, so that implicit solvers and gradients see no kink:

    - contact: delta+ = (delta + sqrt(delta^2 + eps^2))/2 (a softplus of width
      `eps`), and the damping is switched on by delta+/sqrt(delta^2 + eps^2)
      (a smooth step of width eps);
    - friction: F_h = -mu FricDamp |F_z| v_h / sqrt(F_z^2 + (FricDamp |v_h|)^2),
      equal to MoorDyn's law in both limits (slow: -mu FricDamp v_h; fast:
      mu |F_z| against v_h) and smooth through v_h = 0.

    **Arguments:**

    - `depth`: water depth, m (> 0; the seabed is the plane z = -depth).
    - `kBot`: seabed stiffness per area, Pa/m (MoorDyn's default 3e6).
    - `cBot`: seabed damping per area, Pa s/m (default 3e5).
    - `friction`: friction coefficient mu (MoorDyn's FrictionCoefficient, default 0).
    - `fric_damp`: slope of the friction at low speed per mu, N s/m (default 200).
    - `eps`: width of the smooth contact edge, m (default 1e-3).
    """

    depth: Float[Array, ""] = eqx.field(converter=_f64)
    kBot: Float[Array, ""] = eqx.field(converter=_f64, default=3.0e6)
    cBot: Float[Array, ""] = eqx.field(converter=_f64, default=3.0e5)
    friction: Float[Array, ""] = eqx.field(converter=_f64, default=0.0)
    fric_damp: Float[Array, ""] = eqx.field(converter=_f64, default=200.0)
    eps: Float[Array, ""] = eqx.field(converter=_f64, default=1e-3)

    def __check_init__(self):
        for name, unit in (
            ("depth", "m"),
            ("kBot", "Pa/m"),
            ("cBot", "Pa s/m"),
            ("friction", ""),
            ("fric_damp", "N s/m"),
            ("eps", "m"),
        ):
            check_shape(name, getattr(self, name), (), unit)
            check_nonnegative(name, getattr(self, name), unit)

    def forces(self, t, kin, env):
        del t, env
        delta = -self.depth - kin.positions[:, 2]
        root = jnp.sqrt(delta**2 + self.eps**2)
        pen = 0.5 * (delta + root)
        on = pen / root
        area = kin.diameter * kin.length
        vz = kin.velocities[:, 2]
        fz = (self.kBot * pen - self.cBot * vz * on) * area
        vh = kin.velocities[:, :2]
        speed2 = jnp.sum(vh * vh, axis=-1)
        c = self.fric_damp
        den = jnp.sqrt(fz**2 + c**2 * speed2 + (1e-12 * c) ** 2)
        fh = -(self.friction * c * jnp.abs(fz) / den)[:, None] * vh
        nodes = jnp.concatenate([fh, fz[:, None]], axis=1)
        return LineForces(nodes=nodes, points=jnp.zeros_like(kin.point_positions))
