"""`SolveConfig`: every setting of a solve, and the one table of its defaults.

Every function that integrates a scene -- `simulate`, `fit`, `value_and_grad`,
`gauss_newton`, `least_squares`, `sweep` -- takes a `SolveConfig` as `config=` and
its fields as keyword shortcuts (`rtol=1e-8` is `config.replace(rtol=1e-8)`). The
defaults live in `SOLVE_DEFAULTS`, one row per purpose; docs/numerics.md ("Solve
defaults") gives the measurements each row was chosen from.
"""

import dataclasses
import functools
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._arrays import host_op
from ._lazy import diffrax as dfx, is_instance
from ._solvers.names import ADJOINTS, STEP_CONTROLS, check_solver, is_adaptive
from ._validate import (
    check_bool,
    check_choice,
    check_int,
    check_positive,
    check_times,
)


PURPOSES = ("simulate", "identify", "sweep")
"""What a solve is for: one row of `SOLVE_DEFAULTS` each."""

# One row per purpose; a field a row does not name takes the row "simulate"'s value.
# Identification differentiates many solves of one scene; its tolerance is the
# simulate row's, which recovered the parameters of the identification studies
# within their standard deviations at a third of the time of 1e-8 (docs/numerics.md).
SOLVE_DEFAULTS: dict[str, dict[str, Any]] = {
    "simulate": {
        "solver": "kvaerno5",
        "rtol": 1e-6,
        "atol": 1e-6,
        "ts": None,
        "n_save": 201,
        "dt0": None,
        "newton_rtol": None,
        "newton_atol": None,
        "max_steps": 200_000,
        "project": True,
        "adjoint": "auto",
        "checkpoints": "auto",
        "step_control": "auto",
        "progress": False,
        "device": "auto",
    },
    "identify": {},
    # Sweeps run many members of one scene: the solver measured fastest for the
    # scene's system (its "balanced" preset: BDF in displacement variables,
    # Rodas5P in natural variables and for the other systems), which also runs
    # vmapped groups without Newton loops of their own (Rodas5P) or with one
    # Jacobian a step (BDF).
    "sweep": {"solver": "auto"},
}

# The step of a fixed-step solver when `dt0` is not given: the paper's, s.
FIXED_STEP_DT0 = 0.005


def _f64(x):
    """`x` as a float64 array: a NumPy one for a Python or NumPy number (no
    device call; the solve's call moves it), a JAX one for a JAX array or tracer."""
    if x is None or isinstance(x, str):
        return x
    try:
        if isinstance(x, (jax.Array, jax.core.Tracer)):
            return jnp.asarray(x, dtype=jnp.float64)
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        return x  # refused by name in __check_init__


FIELDS = tuple(SOLVE_DEFAULTS["simulate"])


class _plain:
    """A method of `SolveConfig` read as a plain callable. Equinox returns every
    method read from a module as a bound-method module (a pytree, so that it can
    be passed to `jax.jit`), built anew at each read: several a call, a
    measurable part of a small solve's call (docs/performance.md). None of these
    methods is handed to `jax.jit` as a function."""

    def __init__(self, fn):
        self.fn = fn
        functools.update_wrapper(self, fn)

    def __get__(self, obj, cls=None):
        return self.fn if obj is None else functools.partial(self.fn, obj)


class SolveConfig(eqx.Module):
    """Every setting of a solve: solver, step-size control, save times, adjoint,
    limits.

    **Fields** (defaults: the row "simulate" of `jaxstring.SOLVE_DEFAULTS`):

    - `solver`: a name of `jaxstring.SOLVERS`, a `diffrax.AbstractSolver`, or
      `"auto"`: the solver of the "balanced" accuracy preset of the scene's system
      (default `"kvaerno5"`; sweeps: `"auto"`).
    - `rtol`, `atol`: error tolerances of the step-size controller (> 0).
    - `ts`: save times, s, inside the scene's span (None: `n_save` equally spaced
      points over it).
    - `n_save`: number of save times when `ts` is None (>= 2).
    - `dt0`: initial step, s (None: chosen by the controller); the step of a
      fixed-step solver (None: 0.005 s, the paper's).
    - `newton_rtol`, `newton_atol`: tolerances of the implicit stages' Newton
      iteration (None: `rtol`, `atol`).
    - `max_steps`: limit on the number of steps.
    - `project`: project a constrained model's state onto its constraint after
      every step (the Cartesian-tangent string; False shows the drift).
    - `adjoint`: how derivatives go through the solve: `"auto"` (reverse mode for
      the gradient of a scalar loss -- `fit`, `value_and_grad`, `jax.grad`; forward
      mode for the Jacobian of residuals -- `least_squares`, `gauss_newton`),
      `"recursive"` (diffrax's checkpointed reverse mode), `"direct"`,
      `"backsolve"` (continuous adjoint), `"forward"`, `"sensitivity"` (forward
      sensitivities under the solver's error control: accurate through
      slack-and-snap motions; not for projecting models), or a diffrax adjoint.
    - `checkpoints`: checkpoints of the reverse mode: `"auto"` (as many as one
      forward solve takes steps: about one recomputation per step), None
      (diffrax's log-depth recursion) or an int.
    - `step_control`: `"auto"`, `"pid"` or `"newton-limited"` (see
      `jaxstring.NewtonLimitedController`).
    - `progress`: print a text progress meter.
    - `device`: where a single solve runs: `"auto"` (the host CPU, also on a host
      with a GPU: one solve's small kernels run faster there; a sweep's members
      go to the GPUs), `"default"` (JAX's default device) or a `jax.Device`.

    Tolerances, `dt0` and `ts` are arrays (traced: a new value reuses the compiled
    solve); every other field is structure. Build one from a purpose's defaults
    with `SolveConfig.default("identify")`, change fields with `replace`.
    """

    solver: Any = eqx.field(static=True, default="kvaerno5")
    rtol: Any = eqx.field(converter=_f64, default=1e-6)
    atol: Any = eqx.field(converter=_f64, default=1e-6)
    ts: Any = eqx.field(converter=_f64, default=None)
    n_save: int = eqx.field(static=True, default=201)
    dt0: Any = eqx.field(converter=_f64, default=None)
    newton_rtol: Any = eqx.field(converter=_f64, default=None)
    newton_atol: Any = eqx.field(converter=_f64, default=None)
    max_steps: int = eqx.field(static=True, default=200_000)
    project: bool = eqx.field(static=True, default=True)
    adjoint: Any = eqx.field(static=True, default="auto")
    checkpoints: Any = eqx.field(static=True, default="auto")
    step_control: str = eqx.field(static=True, default="auto")
    progress: bool = eqx.field(static=True, default=False)
    device: Any = eqx.field(static=True, default="auto")

    def __check_init__(self):
        check_solver(self.solver)
        check_positive("rtol", self.rtol)
        check_positive("atol", self.atol)
        check_int("n_save", self.n_save, 2)
        check_int("max_steps", self.max_steps, 1)
        check_choice("step_control", self.step_control, STEP_CONTROLS)
        check_bool("project", self.project)
        check_bool("progress", self.progress)
        if self.dt0 is not None:
            check_positive("dt0", self.dt0, "s")
        for name in ("newton_rtol", "newton_atol"):
            if getattr(self, name) is not None:
                check_positive(name, getattr(self, name))
        if not is_instance(self.adjoint, "diffrax", "AbstractAdjoint"):
            check_choice("adjoint", self.adjoint, ADJOINTS)
        if self.checkpoints not in (None, "auto"):
            check_int("checkpoints", self.checkpoints, 1)
        if not isinstance(self.device, jax.Device):
            check_choice("device", self.device, ("auto", "default"))

    @classmethod
    def default(cls, purpose: str = "simulate") -> "SolveConfig":
        """The defaults of `purpose` (one of `PURPOSES`: "simulate", "identify",
        "sweep")."""
        check_choice("purpose", purpose, PURPOSES)
        return _defaults(cls, purpose)

    @_plain
    def replace(self, **fields) -> "SolveConfig":
        """This configuration with `fields` replaced (names of `FIELDS`; checked)."""
        unknown = sorted(set(fields) - set(FIELDS))
        if unknown:
            raise ValueError(
                f"unknown solve option(s) {', '.join(map(repr, unknown))}; valid: "
                f"{', '.join(FIELDS)}."
            )
        converted = {
            name: _CONVERTERS[name](value) if name in _CONVERTERS else value
            for name, value in fields.items()
        }
        new = self.replace_unchecked(**converted)
        new.__check_init__()
        return new

    @_plain
    def replace_unchecked(self, **fields) -> "SolveConfig":
        """`replace` for values already checked (jaxstring's own: the padded
        save count, no save times), without converting and checking every field
        again, which is a measurable part of a small solve's call
        (docs/performance.md, "Compile time")."""
        new = object.__new__(type(self))
        new.__dict__.update(self.__dict__)
        new.__dict__.update(fields)
        return new

    @property
    def adaptive(self) -> bool:
        return is_adaptive(self.solver)

    @_plain
    def newton_tolerances(self):
        """(rtol, atol) of the stage Newton iteration."""
        nr = self.rtol if self.newton_rtol is None else self.newton_rtol
        na = self.atol if self.newton_atol is None else self.newton_atol
        return nr, na

    @_plain
    def initial_step(self):
        """`dt0`, or the fixed step of a fixed-step solver, as an array (None for an
        adaptive solver's own choice)."""
        if self.dt0 is None and not self.adaptive:
            return _f64(FIXED_STEP_DT0)
        return self.dt0

    @_plain
    def save_times(self, t0, t1):
        """`ts`, or `n_save` equally spaced times over [t0, t1], float64."""
        if self.ts is not None:
            return self.ts
        n = self.n_save
        return host_op(lambda xp, a, b: xp.linspace(a, b, n, dtype=xp.float64), t0, t1)

    @_plain
    def adjoint_for(self, derivative: str = "gradient"):
        """The diffrax adjoint of a solve whose derivative is a `"gradient"` of a
        scalar (reverse mode under "auto") or a `"jacobian"` of residuals
        (forward mode under "auto")."""
        if self.adjoint == "auto" and derivative == "jacobian":
            return dfx.ForwardMode()
        from ._adjoints import make_adjoint

        checkpoints = self.checkpoints if isinstance(self.checkpoints, int) else None
        return make_adjoint(self.adjoint, checkpoints)

    @_plain
    def on_cpu(self) -> bool:
        """Whether a single solve of this configuration runs on a CPU (`device`
        "auto" always does)."""
        if self.device == "auto":
            return True
        if self.device == "default":
            return jax.default_backend() == "cpu"
        return self.device.platform == "cpu"

    @_plain
    def solve_device(self):
        """The `jax.Device` a single solve of this configuration runs on."""
        if self.device == "auto":
            return jax.local_devices(backend="cpu")[0]
        if self.device == "default":
            return jax.local_devices()[0]
        return self.device

    @_plain
    def placed(self, tree):
        """`tree` (a solve's arguments) on the configuration's device: the host CPU
        under "auto", as it is under "default"."""
        if self.device == "default":
            return tree
        device = self.device
        if device == "auto":
            if jax.default_backend() == "cpu":
                return tree
            device = jax.local_devices(backend="cpu")[0]
        # Only the arrays move: a solve's arguments also hold functions (a
        # residual, a summary) and other static leaves.
        dynamic, static = eqx.partition(tree, eqx.is_array)
        return eqx.combine(jax.device_put(dynamic, device), static)

    @_plain
    def check_scene(self, scene) -> None:
        """Refuse settings that do not fit `scene` (save times outside its span; an
        adjoint that cannot handle a projecting model), naming the field."""
        if self.ts is not None:
            check_times("ts", self.ts, scene.t0, scene.t1)
        projects = self.project and scene.model.projects
        name = self.adjoint
        if is_instance(name, "diffrax", "AbstractAdjoint"):
            from ._adjoints import SensitivityAdjoint

            name = {
                dfx.BacksolveAdjoint: "backsolve",
                SensitivityAdjoint: "sensitivity",
            }.get(type(name), "")
        if projects and name in ("backsolve", "sensitivity"):
            raise ValueError(
                f"`adjoint={name!r}` does not fit a model that projects onto its "
                f"constraint ({type(scene.model).__name__}); use 'recursive' or "
                "'forward', or project=False."
            )


_CONVERTERS = {
    f.name: f.metadata["converter"]
    for f in dataclasses.fields(SolveConfig)
    if "converter" in f.metadata
}
"""The conversion of each field that has one (`replace` converts the fields it
is given; the others are converted already)."""


@functools.cache
def _defaults(cls, purpose: str) -> SolveConfig:
    """`cls.default(purpose)`, built once (a configuration is immutable)."""
    return cls(**(SOLVE_DEFAULTS["simulate"] | SOLVE_DEFAULTS[purpose]))


def solve_config(
    purpose: str, config: SolveConfig | None = None, **options
) -> SolveConfig:
    """The configuration of a solve for `purpose`: `config` (default: the purpose's
    defaults) with the keyword shortcuts `options` (fields of `SolveConfig`)
    replaced. Raises ValueError naming an unknown option or a bad value."""
    if config is None:
        config = SolveConfig.default(purpose)
    elif not isinstance(config, SolveConfig):
        raise ValueError(
            f"`config` must be a jaxstring SolveConfig; got {type(config).__name__}: "
            f"{config!r}."
        )
    return config.replace(**options) if options else config
