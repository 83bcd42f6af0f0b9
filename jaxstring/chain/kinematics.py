"""Kinematics of a chain of points: link geometry, node axes, and what a chain
hands its loads (`ChainKinematics`) and gets back from them (`ChainForces`)."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import dot
from .._geometry import safe_norm


def unit(x):
    """Unit vectors of the rows of `x` (a zero row stays zero, with a finite
    gradient)."""
    n = safe_norm(x)
    return x / jnp.where(n > 0, n, 1.0)[..., None]


def links(x_lo, x_hi, v_lo, v_hi):
    """Geometry of the links from points `x_lo` to `x_hi` `(L, 3)` moving at `v_lo`,
    `v_hi`: unit directions `(L, 3)`, lengths `(L,)`, length rates `(L,)` and
    relative velocities `(L, 3)`."""
    dx = x_hi - x_lo
    dv = v_hi - v_lo
    length = safe_norm(dx)
    u = dx / jnp.where(length > 0, length, 1.0)[:, None]
    return u, length, dot(u, dv), dv


class ChainForces(eqx.Module):
    """Forces of one load on a chain: `nodes` `(M, 3)` and free `points` `(P, 3)`,
    N."""

    nodes: Float[Array, "M 3"]
    points: Float[Array, "P 3"]

    def __add__(self, other: "ChainForces") -> "ChainForces":
        return ChainForces(self.nodes + other.nodes, self.points + other.points)


class ChainKinematics(eqx.Module):
    """Kinematics and per-node properties of a chain, handed to its loads.

    **Fields** (M nodes, P free points):

    - `positions`, `velocities`: nodes, `(M, 3)`, m and m/s.
    - `tangents`: unit node axes, `(M, 3)` (along the cable).
    - `mass`: lumped node mass, `(M,)`, kg.
    - `volume`: displaced (submerged) node volume, `(M,)`, m^3.
    - `length`: length of cable the node stands for, `(M,)`, m.
    - `wetted_length`: its submerged part, `(M,)`, m (drag acts on it).
    - `diameter`: `(M,)`, m.
    - `Cd`, `CdAx`: the node's own normal and axial drag coefficients, `(M,)`, or
      None where the chain has none (the `Drag` effect then gives them).
    - `point_positions`, `point_velocities`: free points, `(P, 3)`.
    - `point_mass` (kg), `point_volume` (m^3), `point_CdA` (m^2): `(P,)`.
    """

    positions: Float[Array, "M 3"]
    velocities: Float[Array, "M 3"]
    tangents: Float[Array, "M 3"]
    mass: Float[Array, " M"]
    volume: Float[Array, " M"]
    length: Float[Array, " M"]
    wetted_length: Float[Array, " M"]
    diameter: Float[Array, " M"]
    Cd: Float[Array, " M"] | None = None
    CdAx: Float[Array, " M"] | None = None
    point_positions: Float[Array, "P 3"] = eqx.field(
        default_factory=lambda: jnp.zeros((0, 3))
    )
    point_velocities: Float[Array, "P 3"] = eqx.field(
        default_factory=lambda: jnp.zeros((0, 3))
    )
    point_mass: Float[Array, " P"] = eqx.field(default_factory=lambda: jnp.zeros(0))
    point_volume: Float[Array, " P"] = eqx.field(default_factory=lambda: jnp.zeros(0))
    point_CdA: Float[Array, " P"] = eqx.field(default_factory=lambda: jnp.zeros(0))

    @property
    def up(self):
        """The upward unit vector (+z)."""
        return jnp.asarray((0.0, 0.0, 1.0), self.positions.dtype)

    @property
    def masses(self) -> ChainForces:
        """Masses of the nodes and points, in the layout of the forces."""
        return ChainForces(self.mass[:, None], self.point_mass[:, None])

    @property
    def volumes(self) -> ChainForces:
        """Displaced volumes of the nodes and points, in the layout of the forces."""
        return ChainForces(self.volume[:, None], self.point_volume[:, None])

    def zero_forces(self) -> ChainForces:
        return ChainForces(
            jnp.zeros_like(self.positions), jnp.zeros_like(self.point_positions)
        )
