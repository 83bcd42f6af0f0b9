"""A scene: model, effects, environment, initial state and time span."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._effect import AbstractEffect
from ._environment import Environment
from ._model import AbstractModel
from ._validate import check_finite, is_concrete


class Scene(eqx.Module):
    """Everything needed to simulate: model + effects + environment + initial state
    + time span.

    **Arguments:**

    - `model`: any `AbstractModel` (string, tether, vessels).
    - `effects`: tuple of effect Modules. Only these are computed; each must be of a
      kind the model accepts (`model.accepts`), else a ValueError names both.
    - `y0`: initial state in the model's layout.
    - `t1`: end time, s (> t0). `t0`: start time, s.
    - `name`: a label for plots and the command line.
    - `env`: the `Environment` (gravity, water and air density, viscosity, current
      and wind); default `Environment()`.
    """

    model: AbstractModel
    effects: tuple[AbstractEffect, ...]
    y0: Float[Array, "..."]
    t1: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    t0: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    name: str = eqx.field(static=True, default="scene")
    env: Environment = eqx.field(default_factory=Environment)

    def __check_init__(self):
        if not isinstance(self.effects, tuple) or not all(
            isinstance(e, AbstractEffect) for e in self.effects
        ):
            raise ValueError("`effects` must be a tuple of jaxstring effects.")
        kinds = [type(e) for e in self.effects]
        if len(set(kinds)) != len(kinds):
            raise ValueError("`effects` names an effect twice.")
        check_finite("y0", self.y0)
        if not isinstance(self.model, AbstractModel):
            raise ValueError("`model` must be a jaxstring model (AbstractModel).")
        if not isinstance(self.env, Environment):
            raise ValueError(
                f"`env` must be a jaxstring Environment; got {type(self.env).__name__}."
            )
        accepts = self.model.accepts
        for e in self.effects:
            if not isinstance(e, accepts):
                known = ", ".join(k.__name__ for k in accepts)
                raise ValueError(
                    f"effect {type(e).__name__} ({type(e).__module__}) cannot act on "
                    f"model {type(self.model).__name__}: it accepts effects of the "
                    f"kinds {known}."
                )
        expected = tuple(self.model.state_shape())
        if tuple(jnp.shape(self.y0)) != tuple(expected):
            raise ValueError(
                f"`y0` has shape {jnp.shape(self.y0)}; the model needs {expected}."
            )
        if is_concrete(self.t1) and is_concrete(self.t0):
            if not np.isfinite(float(self.t1)) or float(self.t1) <= float(self.t0):
                raise ValueError(
                    f"`t1` must be a finite time > t0 = {float(self.t0)} s; "
                    f"got {self.t1!r}."
                )

    def vector_field(self, t, y):
        """dy/dt of the state under the scene's effects."""
        return self.model.vector_field(t, y, self.effects, self.env)

    def observables(self, y, t=0.0):
        """Derived quantities of one state (see the model's `observables`)."""
        return self.model.observables(t, y, self.effects, self.env)

    def tension(self, y):
        return self.observables(y)["tension"]

    def energy(self, y):
        return self.observables(y)["energy"]

    def has(self, kind: type) -> bool:
        """Whether the scene calls for an effect of this type."""
        return any(isinstance(e, kind) for e in self.effects)


def scene_vector_field(t, y, scene: Scene):
    """diffrax-style vector field: the scene travels as `args`, never closed over."""
    return scene.vector_field(t, y)
