"""A scene: model, effects, environment, initial state and time span."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._arrays import FloatScalar, as_array
from ._effect import AbstractEffect
from ._environment import Environment
from ._model import AbstractModel
from ._programs import eager_jit
from ._validate import check_finite, check_shape, is_concrete, show


def _state(y0):
    # Lists and integer arrays become float arrays; anything that is not numbers is
    # left for `__check_init__` to refuse by name.
    try:
        y = as_array(y0)
    except TypeError:
        return y0
    return y if jnp.issubdtype(y.dtype, jnp.inexact) else as_array(y, np.float64)


def _time(t):
    try:
        return as_array(t)
    except TypeError:
        return t


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
    y0: Float[Array, "..."] = eqx.field(converter=_state)
    t1: FloatScalar = eqx.field(converter=_time)
    t0: FloatScalar = eqx.field(converter=_time, default=0.0)
    name: str = eqx.field(static=True, default="scene")
    env: Environment = eqx.field(default_factory=Environment)

    def __check_init__(self):
        if not isinstance(self.model, AbstractModel):
            raise ValueError(
                "`model` must be a jaxstring model (AbstractModel); got "
                f"{type(self.model).__name__}: {self.model!r}."
            )
        if not isinstance(self.effects, tuple) or not all(
            isinstance(e, AbstractEffect) for e in self.effects
        ):
            raise ValueError(
                "`effects` must be a tuple of jaxstring effects (AbstractEffect); "
                f"got {self.effects!r}."
            )
        kinds = [type(e) for e in self.effects]
        twice = sorted({k.__name__ for k in kinds if kinds.count(k) > 1})
        if twice:
            raise ValueError(
                f"`effects` names {', '.join(twice)} twice; valid: each effect kind "
                "at most once."
            )
        if not hasattr(self.y0, "shape") or not jnp.issubdtype(
            jnp.result_type(self.y0), jnp.inexact
        ):
            raise ValueError(
                "`y0` must be an array of floating-point numbers (the model's state); "
                f"got {self.y0!r}."
            )
        check_finite("y0", self.y0)
        if not isinstance(self.env, Environment):
            raise ValueError(
                "`env` must be a jaxstring Environment; got "
                f"{type(self.env).__name__}: {self.env!r}."
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
        for name in ("t0", "t1"):
            t = getattr(self, name)
            if not isinstance(t, jax.Array) or not jnp.issubdtype(t.dtype, jnp.number):
                raise ValueError(f"`{name}` must be a time in s (a number); got {t!r}.")
            check_shape(name, t, (), "s")
        check_finite("t0", self.t0)
        if is_concrete(self.t1) and is_concrete(self.t0):
            if not np.isfinite(float(self.t1)) or float(self.t1) <= float(self.t0):
                raise ValueError(
                    f"`t1` must be a finite time > t0 = {float(self.t0):g} s; "
                    f"got {show(self.t1)}."
                )

    def vector_field(self, t, y):
        """dy/dt of the state under the scene's effects (compiled as one program
        when called on concrete arrays)."""
        return _vector_field(self, _time_array(t), jnp.asarray(y))

    def observables(self, y, t=0.0):
        """Derived quantities of one state (see the model's `observables`).

        Compiled as one program (per scene structure), so that a call on concrete
        arrays does not dispatch, and compile, each of its many small operations
        one by one."""
        return _observables(self, jnp.asarray(y), _time_array(t))

    def tension(self, y):
        return self.observables(y)["tension"]

    def energy(self, y):
        return self.observables(y)["energy"]

    @property
    def structure(self):
        """What the implicit solvers may assume of the scene's vector field (the
        model's `SolverStructure` under the scene's effects)."""
        return self.model.structure(self.effects)

    def has(self, kind: type) -> bool:
        """Whether the scene calls for an effect of this type."""
        return any(isinstance(e, kind) for e in self.effects)


def scene_vector_field(t, y, scene: Scene):
    """diffrax-style vector field: the scene travels as `args`, never closed over."""
    return _traced_vector_field(t, y, scene)


@functools.partial(eqx.filter_jit, inline=True)
def _traced_vector_field(t, y, scene):
    # Jitted (and inlined where it is called) so that its trace is kept: a solve
    # calls the vector field from many places (stages, Jacobians, the solver's
    # start) with arguments of one structure, and traces it once.
    return scene.vector_field(t, y)


def _time_array(t):
    return t if isinstance(t, jax.Array) else jnp.asarray(t, dtype=jnp.float64)


@eager_jit
def _observables(scene, y, t):
    return scene.model.observables(t, y, scene.effects, scene.env)


@eager_jit
def _vector_field(scene, t, y):
    return scene.model.vector_field(t, y, scene.effects, scene.env)
