"""Effects on an underwater tether: weight, buoyancy and hydrodynamic drag in a current.

Source: O. Blintsov, "Development of the mathematical modeling method for dynamics of
the flexible tether as an element of the underwater complex", Eastern-European
Journal of Enterprise Technologies 1/7 (85), 2017, doi:10.15587/1729-4061.2017.90291,
section 4.2 (eq 1 and the drag equations).

Every effect here is an ``AbstractTetherLoad``: it maps the kinematics of the tether
elements (positions, velocities, unit tangents) to a force on each element, shape
``(N, 3)``, in the earth frame (x north, y east-ish, z up). The tether model sums the
loads of the effects a scene names; an effect that is not named is never traced (so a
scene without ``Drag`` has no drag operation in its vector field).

Added mass is a parameter of the tether model (``added_mass``), not an effect: it
changes the inertia mu_n of every element, which the tension solvers need.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._geometry import safe_norm
from .._validate import check_finite, check_nonnegative, is_concrete
from ..pendulum.effects import AbstractEffect


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
    """

    positions: Float[Array, "N 3"]
    velocities: Float[Array, "N 3"]
    tangents: Float[Array, "N 3"]


class AbstractTetherLoad(AbstractEffect):
    """An effect that applies an external force to every tether element."""

    @abc.abstractmethod
    def forces(self, t, kin: TetherKinematics, model) -> Float[Array, "N 3"]:
        """Force on each element at time `t` (s), N, shape `(N, 3)`."""

    @abc.abstractmethod
    def potential(self, kin: TetherKinematics, model) -> Float[Array, " N"]:
        """Potential energy of the load per element, J (0 if non-conservative).

        Per element so that the model can leave out elements that are coiled on the
        winch drum.
        """


class Weight(AbstractTetherLoad):
    """Gravity on the element masses: F_g(n) = m_n g e, e pointing down (-z).

    **Arguments:**

    - `g`: gravitational acceleration, m/s^2 (>= 0).
    """

    g: Float[Array, ""] = eqx.field(converter=_f64, default=9.81)

    def __check_init__(self):
        check_nonnegative("g", self.g, "m/s^2")

    def forces(self, t, kin, model):
        del t
        up = jnp.asarray(_UP, kin.positions.dtype)
        f = -model.element_mass * self.g * up
        return jnp.broadcast_to(f, kin.positions.shape)

    def potential(self, kin, model):
        return model.element_mass * self.g * kin.positions[:, 2]


class Buoyancy(AbstractTetherLoad):
    """Buoyancy of the displaced water: F_b(n) = -rho Q_n g e (upwards, +z).

    The water density is the tether model's `rho_water`, Q_n its element volume.

    **Arguments:**

    - `g`: gravitational acceleration, m/s^2 (>= 0).
    """

    g: Float[Array, ""] = eqx.field(converter=_f64, default=9.81)

    def __check_init__(self):
        check_nonnegative("g", self.g, "m/s^2")

    def forces(self, t, kin, model):
        del t
        up = jnp.asarray(_UP, kin.positions.dtype)
        f = model.rho_water * model.element_volume * self.g * up
        return jnp.broadcast_to(f, kin.positions.shape)

    def potential(self, kin, model):
        return -model.rho_water * model.element_volume * self.g * kin.positions[:, 2]


# ---------------------------------------------------------------------------
# Current fields


class AbstractCurrent(eqx.Module):
    """A current: water velocity (m/s) at positions `(M, 3)` and time `t` (s)."""

    @abc.abstractmethod
    def __call__(self, t, positions) -> Float[Array, "M 3"]:
        """Water velocity at each position, m/s, shape `(M, 3)`."""


class UniformCurrent(AbstractCurrent):
    """The same water velocity everywhere (the paper: v_c = (-1, 0, 0) m/s).

    **Arguments:**

    - `velocity`: shape `(3,)`, m/s.
    """

    velocity: Float[Array, "3"] = eqx.field(converter=_f64)

    def __check_init__(self):
        if jnp.shape(self.velocity) != (3,):
            raise ValueError(
                "`velocity` must have shape (3,) (m/s); got "
                f"{jnp.shape(self.velocity)}."
            )
        check_finite("velocity", self.velocity)

    def __call__(self, t, positions):
        del t
        return jnp.broadcast_to(self.velocity, positions.shape)


class DepthProfileCurrent(AbstractCurrent):
    """A horizontal-layer current: velocity interpolated linearly in height z.

    Above the highest and below the lowest station the end values hold.

    **Arguments:**

    - `z`: heights of the stations, shape `(K,)`, m, strictly increasing (z up, so a
      depth D is z = -D).
    - `velocity`: water velocity at the stations, shape `(K, 3)`, m/s.
    """

    z: Float[Array, " K"] = eqx.field(converter=_f64)
    velocity: Float[Array, "K 3"] = eqx.field(converter=_f64)

    def __check_init__(self):
        if jnp.ndim(self.z) != 1 or jnp.shape(self.z)[0] < 1:
            raise ValueError("`z` must be a 1-d array of station heights, m.")
        if jnp.shape(self.velocity) != (jnp.shape(self.z)[0], 3):
            raise ValueError(
                f"`velocity` must have shape (K, 3) = ({jnp.shape(self.z)[0]}, 3) "
                f"(m/s); got {jnp.shape(self.velocity)}."
            )
        check_finite("z", self.z)
        check_finite("velocity", self.velocity)
        if is_concrete(self.z) and np.any(np.diff(np.asarray(self.z)) <= 0):
            raise ValueError(f"`z` must be strictly increasing (m); got {self.z!r}.")

    def __call__(self, t, positions):
        del t
        zq = positions[:, 2]
        interp = jax.vmap(lambda col: jnp.interp(zq, self.z, col), out_axes=1)
        return interp(self.velocity.T)


class FunctionCurrent(AbstractCurrent):
    """Any JAX function of time and position: `fn(t, positions, params) -> (M, 3)`.

    `fn` is structure (static); its parameters go in `params` (a PyTree of arrays)
    so that they stay differentiable and vmappable, never closed over.

    **Arguments:**

    - `fn`: callable `(t, positions (M, 3), params) -> velocities (M, 3)`, m/s.
    - `params`: PyTree of arrays handed to `fn` (default: none).
    """

    fn: object = eqx.field(static=True)
    params: object = None

    def __check_init__(self):
        if not callable(self.fn):
            raise ValueError(f"`fn` must be callable; got {self.fn!r}.")

    def __call__(self, t, positions):
        return self.fn(t, positions, self.params)


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
    - `current`: an `AbstractCurrent` (uniform, depth profile, any function), or
      `None` for still water (then no current operation is traced).
    """

    c_t: Float[Array, ""] = eqx.field(converter=_f64, default=0.1)
    c_n: Float[Array, ""] = eqx.field(converter=_f64, default=1.0)
    c_l: Float[Array, ""] = eqx.field(converter=_f64, default=0.0)
    current: AbstractCurrent | None = None

    def __check_init__(self):
        check_nonnegative("c_t", self.c_t)
        check_nonnegative("c_n", self.c_n)
        check_nonnegative("c_l", self.c_l)
        if self.current is not None and not isinstance(self.current, AbstractCurrent):
            raise ValueError(
                "`current` must be a jaxstring current field (UniformCurrent, "
                f"DepthProfileCurrent, FunctionCurrent) or None; got {self.current!r}."
            )

    def relative_velocity(self, t, kin):
        """v_f = v - v_c(p, t), m/s, shape `(N, 3)`."""
        if self.current is None:
            return kin.velocities
        return kin.velocities - self.current(t, kin.positions)

    def forces(self, t, kin, model):
        vf = self.relative_velocity(t, kin)
        i = kin.tangents
        v_t = jnp.sum(vf * i, axis=-1, keepdims=True)
        v_perp = vf - v_t * i
        v_n = safe_norm(v_perp, keepdims=True)
        half_rho_d_l = 0.5 * model.rho_water * model.d * model.element_length
        return -half_rho_d_l * (
            jnp.pi * self.c_t * v_t * jnp.abs(v_t) * i
            + self.c_n * v_n * v_perp
            + self.c_l * v_t * jnp.cross(i, vf)
        )

    def potential(self, kin, model):
        del model
        return jnp.zeros(kin.positions.shape[:1], kin.positions.dtype)


HYDRO_EFFECTS = {
    "weight": Weight,
    "buoyancy": Buoyancy,
    "drag": Drag,
}
