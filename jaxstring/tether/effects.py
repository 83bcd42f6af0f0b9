"""Effects on an underwater tether: weight, buoyancy and hydrodynamic drag in a current.

Source: O. Blintsov, "Development of the mathematical modeling method for dynamics of
the flexible tether as an element of the underwater complex", Eastern-European
Journal of Enterprise Technologies 1/7 (85), 2017, doi:10.15587/1729-4061.2017.90291,
section 4.2 (eq 1 and the drag equations).

Every effect here is an ``AbstractTetherLoad`` (the one protocol of
``jaxstring.AbstractLoad``): ``forces(t, kin, env)`` maps the kinematics of the tether
elements (positions, velocities, unit tangents, element mass, volume, length and
diameter) and the scene's ``Environment`` (g, water density, current) to a force on
each element, shape ``(N, 3)``, in the earth frame (x north, y east, z up). The tether
model sums the loads of the effects a scene names; an effect that is not named is
never traced (so a scene without ``Drag`` has no drag operation in its vector field).
Weight and buoyancy are constant loads: their potential is minus their work.

Added mass is a parameter of the tether model (``added_mass``), not an effect: it
changes the inertia mu_n of every element, which the tension solvers need.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._effect import AbstractLoad
from .._environment import (
    AbstractCurrent as AbstractCurrent,
    DepthProfileCurrent as DepthProfileCurrent,
    FunctionCurrent as FunctionCurrent,
    UniformCurrent as UniformCurrent,
)
from .._geometry import safe_norm
from .._validate import check_nonnegative


def _f64(x):
    return jnp.asarray(x, dtype=jnp.float64)


_UP = (0.0, 0.0, 1.0)  # z is up (the paper's Oxyz: x north, z vertically upwards)


class TetherKinematics(eqx.Module):
    """Kinematics of the tether elements, handed to the loads.

    **Fields:**

    - `positions`: element positions, shape `(N, 3)`, m.
    - `velocities`: element velocities, shape `(N, 3)`, m/s.
    - `tangents`: unit vector of each element's axis O_n x_n (from element n towards
      the next point of the cable, the paper's i_n), shape `(N, 3)`.
    - `mass`: mass of one element, kg. `volume`: its displaced volume, m^3.
    - `length`: length of cable one element stands for, m. `diameter`: m.
    """

    positions: Float[Array, "N 3"]
    velocities: Float[Array, "N 3"]
    tangents: Float[Array, "N 3"]
    mass: Float[Array, ""]
    volume: Float[Array, ""]
    length: Float[Array, ""]
    diameter: Float[Array, ""]


class AbstractTetherLoad(AbstractLoad):
    """An effect that applies an external force to every tether element.

    `constant`: True when the force depends on neither the state nor time (its
    potential is then minus its work, per element)."""

    constant: ClassVar[bool] = False

    @abc.abstractmethod
    def forces(self, t, kin: TetherKinematics, env) -> Float[Array, "N 3"]:
        """Force on each element at time `t` (s), N, shape `(N, 3)`."""


class Weight(AbstractTetherLoad):
    """Gravity on the element masses: F_g(n) = m_n g e, e pointing down (-z), with g
    the scene's `Environment.g`."""

    constant: ClassVar[bool] = True

    def forces(self, t, kin, env):
        del t
        up = jnp.asarray(_UP, kin.positions.dtype)
        return jnp.broadcast_to(-kin.mass * env.g * up, kin.positions.shape)


class Buoyancy(AbstractTetherLoad):
    """Buoyancy of the displaced water: F_b(n) = -rho Q_n g e (upwards, +z), with rho
    and g from the scene's `Environment`, Q_n the element volume."""

    constant: ClassVar[bool] = True

    def forces(self, t, kin, env):
        del t
        up = jnp.asarray(_UP, kin.positions.dtype)
        f = env.rho_water * kin.volume * env.g * up
        return jnp.broadcast_to(f, kin.positions.shape)


# ---------------------------------------------------------------------------
# Drag


class Drag(AbstractTetherLoad):
    """Quadratic hydrodynamic drag on the velocity relative to the current.

    With v_f = v_n - v_c(p_n, t) and the element frame of the paper (i_n along the
    cable, k_n = i_n x v_f / |i_n x v_f|, j_n = k_n x i_n), the components of v_f are
    tangential v_ft = v_f . i_n, normal v_fn = |v_f - v_ft i_n| (>= 0) and lateral
    v_fl = v_f . k_n = 0 (k_n is normal to v_f by construction). The drag is

    - tangential: F_ft = -1/2 rho D_t c_t v_ft |v_ft|, D_t = pi d l_e (wetted surface),
    - normal: F_fn = -1/2 rho D_n c_n v_fn^2 along j_n, D_n = d l_e (projected area),
    - lateral: F_fl = -1/2 rho D_l c_l v_fn v_ft along k_n, D_l = d l_e,

    with l_e the length of cable an element stands for. The lateral law is the one
    printed in the paper (a cross-flow "lift"); a law v_fl |v_fl| would vanish
    identically in this frame. Written without normalising k_n and j_n
    (v_fn j_n = v_f - v_ft i_n, v_fn k_n = i_n x v_f), so the force is exactly zero
    at zero relative velocity and its gradient is finite there (the norm goes through
    a double-where).

    **Arguments:**

    - `c_t`, `c_n`, `c_l`: tangential, normal and lateral drag coefficients (>= 0).
      Paper Table 1: 0.1, 1.0, 0.0.

    The current is the scene's `Environment.current` (uniform, depth profile, any
    function; still water without one, and then no current operation is traced);
    rho is `Environment.rho_water`.
    """

    c_t: Float[Array, ""] = eqx.field(converter=_f64, default=0.1)
    c_n: Float[Array, ""] = eqx.field(converter=_f64, default=1.0)
    c_l: Float[Array, ""] = eqx.field(converter=_f64, default=0.0)

    def __check_init__(self):
        check_nonnegative("c_t", self.c_t)
        check_nonnegative("c_n", self.c_n)
        check_nonnegative("c_l", self.c_l)

    @staticmethod
    def relative_velocity(t, kin, env):
        """v_f = v - v_c(p, t), m/s, shape `(N, 3)`."""
        if env.current is None:
            return kin.velocities
        return kin.velocities - env.current(t, kin.positions)

    def forces(self, t, kin, env):
        vf = self.relative_velocity(t, kin, env)
        i = kin.tangents
        v_t = jnp.sum(vf * i, axis=-1, keepdims=True)
        v_perp = vf - v_t * i
        v_n = safe_norm(v_perp, keepdims=True)
        half_rho_d_l = 0.5 * env.rho_water * kin.diameter * kin.length
        return -half_rho_d_l * (
            jnp.pi * self.c_t * v_t * jnp.abs(v_t) * i
            + self.c_n * v_n * v_perp
            + self.c_l * v_t * jnp.cross(i, vf)
        )


HYDRO_EFFECTS = {
    "weight": Weight,
    "buoyancy": Buoyancy,
    "drag": Drag,
}
