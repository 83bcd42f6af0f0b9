"""The environment a scene lives in: gravity, fluid properties, current and wind.

Every physical constant that more than one effect reads lives here, once. A scene
carries one `Environment`; fits and sweeps vary its leaves (`env.g`,
`env.rho_water`, `env.current.velocity`, ...) like any other parameter.
"""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._arrays import FloatScalar, f64
from ._validate import (
    check_fields,
    check_finite,
    is_concrete,
)


# Gravity of the papers and specs (m/s^2) and sea-water density (kg/m^3, the tandem
# spec): the defaults of `Environment` and of every scene that takes them.
G = 9.81
RHO_SEA_WATER = 1025.0


class AbstractFlow(eqx.Module):
    """A fluid velocity field (current or wind): m/s at positions `(M, 3)` and time t.

    Positions are in the earth frame of the model that asks (for the tether and the
    tandem: x north, y east, z up; the tandem asks at the surface, z = 0).
    """

    @abc.abstractmethod
    def __call__(self, t, positions) -> Float[Array, "M 3"]:
        """Fluid velocity at each position, m/s, shape `(M, 3)`."""


class UniformCurrent(AbstractFlow):
    """The same velocity everywhere (the tether paper: v_c = (-1, 0, 0) m/s).

    Serves for a uniform wind too (`Environment(wind=UniformCurrent(...))`).

    **Arguments:**

    - `velocity`: shape `(3,)`, m/s.
    """

    velocity: Float[Array, "3"] = eqx.field(converter=f64)

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


class DepthProfileCurrent(AbstractFlow):
    """A horizontal-layer current: velocity interpolated linearly in height z.

    Above the highest and below the lowest station the end values hold.

    **Arguments:**

    - `z`: heights of the stations, shape `(K,)`, m, strictly increasing (z up, so a
      depth D is z = -D).
    - `velocity`: water velocity at the stations, shape `(K, 3)`, m/s.
    """

    z: Float[Array, " K"] = eqx.field(converter=f64)
    velocity: Float[Array, "K 3"] = eqx.field(converter=f64)

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


class FunctionCurrent(AbstractFlow):
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


# The name the tether's users know.
AbstractCurrent = AbstractFlow


class Environment(eqx.Module):
    """Gravity, fluid properties and the fluid velocity fields of a scene.

    **Arguments:**

    - `g`: gravitational acceleration, m/s^2 (>= 0). It acts along minus the
      model's vertical axis (`model.vertical`: y for the string pendulum, whose
      paper works in the x-y plane; z for the tether and the tandem).
    - `rho_water`: water density, kg/m^3 (> 0). Default 1025 (sea water, the
      tandem spec); the tether paper's scenes use 1024 (its Table 1).
    - `rho_air`: air density, kg/m^3 (> 0).
    - `nu_water`: kinematic viscosity of water, m^2/s (> 0).
    - `current`: the water velocity field (`UniformCurrent`, `DepthProfileCurrent`,
      `FunctionCurrent`), or None for still water (then no current operation is
      traced).
    - `wind`: the air velocity field at the surface, or None for no wind.
    """

    g: FloatScalar = eqx.field(converter=f64, default=G)
    rho_water: FloatScalar = eqx.field(converter=f64, default=RHO_SEA_WATER)
    rho_air: FloatScalar = eqx.field(converter=f64, default=1.225)
    nu_water: FloatScalar = eqx.field(converter=f64, default=1.0e-6)
    current: AbstractFlow | None = None
    wind: AbstractFlow | None = None

    def __check_init__(self):
        check_fields(
            self,
            positive={"rho_water": "kg/m^3", "rho_air": "kg/m^3", "nu_water": "m^2/s"},
            nonnegative={"g": "m/s^2"},
        )
        for name in ("current", "wind"):
            field = getattr(self, name)
            if field is not None and not isinstance(field, AbstractFlow):
                raise ValueError(
                    f"`{name}` must be a jaxstring velocity field (UniformCurrent, "
                    f"DepthProfileCurrent, FunctionCurrent) or None; got {field!r}."
                )

    def water_velocity(self, t, positions):
        """Current at `positions` `(M, 3)`, m/s; zeros in still water."""
        if self.current is None:
            return jnp.zeros_like(positions)
        return self.current(t, positions)

    def air_velocity(self, t, positions):
        """Wind at `positions` `(M, 3)`, m/s; zeros without wind."""
        if self.wind is None:
            return jnp.zeros_like(positions)
        return self.wind(t, positions)
