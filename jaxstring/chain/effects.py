"""Loads on the points of a chain: weight, buoyancy and Morison drag in a current.

A chain -- the tether's elements, a mooring network's line nodes and free points,
the tandem's line -- hands its loads a `ChainKinematics`: positions, velocities and
axes of its nodes, the cable each node stands for, and its free points. A load maps
`(t, kin, env)` to `ChainForces` (one force per node and per free point, N, in the
earth frame: x, y horizontal, z up, the still-water surface at z = 0). The model
turns the forces into accelerations; an effect a scene does not name is never
traced.

`Gravity` and `Buoyancy` act on any model whose kinematics give the masses and
displaced volumes of its material points in the layout of its forces
(`kin.masses`, `kin.volumes`) and its upward unit vector (`kin.up`): the chains
here and the string pendulum (whose vertical is y).
"""

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu

from .._arrays import FloatScalar, f64
from .._effect import AbstractLoad
from .._geometry import safe_norm
from .._validate import check_choice, check_nonnegative, check_shape
from .kinematics import ChainForces


def _none_or_f64(x):
    return None if x is None else f64(x)


class AbstractChainLoad(AbstractLoad):
    """A load on the nodes and free points of a chain:
    `forces(t, kin: ChainKinematics, env) -> ChainForces`."""


class Gravity(AbstractLoad):
    """Weight: F = -m g e_up on every material point (line density mu g for the
    string pendulum), with g the scene's `Environment.g` and e_up the model's
    vertical (z for chains, y for the string pendulum)."""

    constant = True

    def forces(self, t, kin, env):
        del t
        down = -env.g * kin.up
        return jtu.tree_map(lambda m: m * down, kin.masses)


class Buoyancy(AbstractLoad):
    """Buoyancy of the displaced water: F = rho V g e_up on every material point
    with a displaced volume V, rho and g from the scene's `Environment`."""

    constant = True

    def forces(self, t, kin, env):
        del t
        up = env.rho_water * env.g * kin.up
        return jtu.tree_map(lambda v: v * up, kin.volumes)


class Drag(AbstractChainLoad):
    """Quadratic (Morison) drag on the velocity relative to the current.

    With the water's velocity relative to a node, u = v_c(p, t) - v, split along
    the node axis q (u_q = (u . q) q) and across it (u_p = u - u_q), a node of
    diameter d standing for the wetted length l_s gets

        F = 1/2 rho d l_s (Cd |u_p| u_p + a CdAx |u_q| u_q - Cl (u . q) q x u),

    the normal drag on the projected area d l_s, the axial drag on the wetted
    surface pi d l_s (`axial_area="surface"`, a = pi: MoorDyn's and Blintsov's) or
    on d l_s (`"diameter"`, a = 1: DNV-OS-E301's and OrcaFlex's chain
    coefficients), and Blintsov's lateral "lift" F_fl = -1/2 rho d l_s Cl v_fn v_ft
    (a cross-flow force normal to the axis and to the flow; O. Blintsov, Eastern-
    European Journal of Enterprise Technologies 1/7 (85), 2017, section 4.2). A free
    point gets 1/2 rho CdA |u| u. The norms go through a double-where, so the force
    and its gradient are finite (zero) at zero relative velocity.

    A deck whose CdAx was converted from DNV or OrcaFlex chain values (1.15 / 1.8
    = 0.64 on the 1.8 d volumetric diameter) gets pi times their axial drag in
    MoorDyn; `axial_area="diameter"` applies such a coefficient as meant.

    **Arguments:**

    - `Cd`, `CdAx`: normal and axial coefficients (>= 0). None (default): each
      node's own, from its line type (a MoorDyn deck); a chain without line types
      (the tether) needs them given (Blintsov's Table 1: Cd = 1.0, CdAx = 0.1).
    - `Cl`: the lateral coefficient (>= 0; default None: no lateral force).
    - `scale`: a factor on every coefficient (default 1; MoorDyn's CdScaleIC uses
      > 1 to damp a relaxation).
    - `axial_area`: `"surface"` (default) or `"diameter"`, see above.

    The current is the scene's `Environment.current` (still water without one,
    and then no current operation is traced); rho is `Environment.rho_water`.
    """

    Cd: FloatScalar | None = eqx.field(converter=_none_or_f64, default=None)
    CdAx: FloatScalar | None = eqx.field(converter=_none_or_f64, default=None)
    Cl: FloatScalar | None = eqx.field(converter=_none_or_f64, default=None)
    scale: FloatScalar = eqx.field(converter=f64, default=1.0)
    axial_area: str = eqx.field(static=True, default="surface")

    def __check_init__(self):
        for name in ("Cd", "CdAx", "Cl", "scale"):
            value = getattr(self, name)
            if value is not None:
                check_shape(name, value, ())
                check_nonnegative(name, value)
        check_choice("axial_area", self.axial_area, ("surface", "diameter"))

    def _coefficient(self, name, kin):
        own = getattr(self, name)
        if own is not None:
            return own
        per_node = getattr(kin, name)
        if per_node is None:
            raise ValueError(
                f"`Drag.{name}` must be given for a chain without line types (a "
                f"tether): e.g. Drag(Cd=1.0, CdAx=0.1); got {name}=None."
            )
        return per_node[:, None]

    def forces(self, t, kin, env):
        u = -kin.velocities
        if env.current is not None:
            u = u + env.current(t, kin.positions)
        q = kin.tangents
        u_ax = jnp.sum(u * q, axis=-1, keepdims=True)
        uq = u_ax * q
        up = u - uq
        n_up = safe_norm(up, keepdims=True)
        area = jnp.pi if self.axial_area == "surface" else 1.0
        Cd = self._coefficient("Cd", kin)
        CdAx = self._coefficient("CdAx", kin)
        f = Cd * n_up * up + area * CdAx * jnp.abs(u_ax) * uq
        if self.Cl is not None:
            f = f - self.Cl * u_ax * jnp.cross(q, u)
        half = 0.5 * env.rho_water * kin.diameter * kin.wetted_length
        nodes = self.scale * half[:, None] * f
        if kin.point_positions.shape[0] == 0:
            return ChainForces(nodes, jnp.zeros_like(kin.point_positions))
        pu = -kin.point_velocities
        if env.current is not None:
            pu = pu + env.current(t, kin.point_positions)
        points = (0.5 * env.rho_water * self.scale * kin.point_CdA)[:, None] * (
            safe_norm(pu, keepdims=True) * pu
        )
        return ChainForces(nodes, points)
