"""simulate(scene, ...) -> Trajectory, and the one solve behind simulate, fit, sweep."""

import dataclasses
from typing import Any

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np

from . import _programs
from ._jit import cpu_jit
from ._scene import Scene, scene_vector_field
from ._sensitivity import SensitivityAdjoint
from ._solvers.diffrax_compat import result_code, result_from_code
from ._solvers.presets import ACCURACY_PRESETS, resolve_preset
from ._solvers.projected import ProjectedSolver
from ._solvers.registry import build_solver, check_solver, is_adaptive
from ._solvers.step_size import STEP_CONTROLS, make_controller
from ._trajectory import Trajectory
from ._validate import (
    check_bool,
    check_choice,
    check_int,
    check_positive,
    check_times,
)


ADJOINTS = ("recursive", "direct", "backsolve", "forward", "sensitivity")


def make_adjoint(adjoint, checkpoints=None):
    """A diffrax adjoint from a name (`"recursive"`, `"direct"`, `"backsolve"`,
    `"forward"`, `"sensitivity"`: `SensitivityAdjoint`) or a
    `diffrax.AbstractAdjoint` instance (returned as is)."""
    if isinstance(adjoint, dfx.AbstractAdjoint):
        return adjoint
    if adjoint is None:
        adjoint = "recursive"
    check_choice("adjoint", adjoint, ADJOINTS)
    if adjoint == "recursive":
        return dfx.RecursiveCheckpointAdjoint(checkpoints=checkpoints)
    if adjoint == "direct":
        return dfx.DirectAdjoint()
    if adjoint == "backsolve":
        return dfx.BacksolveAdjoint()
    if adjoint == "sensitivity":
        return SensitivityAdjoint()
    return dfx.ForwardMode()


class SolveConfig(eqx.Module):
    """Solver settings of a solve.

    Same meaning as the arguments of `jaxstring.simulate`; `adjoint` is a diffrax
    adjoint (see `make_adjoint`; None: diffrax's default, recursive checkpointing).
    Tolerances and `dt0` given as arrays are traced (new values reuse the compiled
    solve, as in `simulate`); as Python floats they are compiled in. Every other
    field is structure.
    """

    solver: Any = eqx.field(static=True, default="kvaerno5")
    rtol: Any = 1e-6
    atol: Any = 1e-6
    n_save: int = eqx.field(static=True, default=201)
    dt0: Any = None
    newton_rtol: Any = None
    newton_atol: Any = None
    max_steps: int = eqx.field(static=True, default=200_000)
    project: bool = eqx.field(static=True, default=True)
    adjoint: Any = eqx.field(static=True, default=None)
    step_control: str = eqx.field(static=True, default="auto")
    progress: bool = eqx.field(static=True, default=False)

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
        if self.adjoint is not None and not isinstance(
            self.adjoint, dfx.AbstractAdjoint
        ):
            raise ValueError(
                "`adjoint` must be a diffrax adjoint (use make_adjoint(name)); "
                f"got {self.adjoint!r}."
            )


class _ProjectedSolverAD(ProjectedSolver):
    # diffrax's ForwardMode/DirectAdjoint read `solver.scan_kind` (the wrapped
    # solver's, set below); ProjectedSolver does not forward it.
    @property
    def scan_kind(self):
        return getattr(self.solver, "scan_kind", None)


def _default_adjoint(adjoint) -> bool:
    return adjoint is None or (
        type(adjoint) is dfx.RecursiveCheckpointAdjoint and adjoint.checkpoints is None
    )


def solver_parts(scene: Scene, config: SolveConfig):
    """The diffrax solver (before any projection wrapper), step-size controller and
    initial step of `scene` under `config`, as every solve builds them."""
    f64 = lambda x: jnp.asarray(x, dtype=jnp.float64)
    adaptive = is_adaptive(config.solver)
    dt0 = config.dt0
    if not adaptive and dt0 is None:
        dt0 = 0.005  # the paper's step
    dt0 = None if dt0 is None else f64(dt0)
    nr = config.rtol if config.newton_rtol is None else config.newton_rtol
    na = config.atol if config.newton_atol is None else config.newton_atol
    solver = build_solver(config.solver, f64(nr), f64(na), scene)
    controller = make_controller(
        config.solver, f64(config.rtol), f64(config.atol), adaptive, config.step_control
    )
    return solver, controller, dt0


def _diffeqsolve(scene: Scene, config: SolveConfig, saveat):
    """diffrax's solution of `scene` under `config`: the solve of `solve`, saved as
    `saveat(fn)` says, with `fn` the projection onto the constraint manifold for a
    projected solve (None: the state as is). E.g. every step:
    `saveat=lambda fn: dfx.SaveAt(steps=True)`.
    """
    adjoint = make_adjoint(config.adjoint)
    if isinstance(adjoint, dfx.BacksolveAdjoint) and scene.model.projects:
        raise ValueError(
            "`adjoint='backsolve'` does not fit a model that projects onto its "
            f"constraint ({type(scene.model).__name__}); use 'recursive'."
        )
    solver, controller, dt0 = solver_parts(scene, config)
    save_fn = None
    if config.project and scene.model.projects:
        if not _default_adjoint(config.adjoint):
            # diffrax sets the stage loop of a Runge-Kutta solver to a kind it can
            # differentiate in forward mode / with DirectAdjoint, but cannot see
            # through the wrapper: do it before wrapping.
            kind = (
                "lax"
                if isinstance(adjoint, dfx.ForwardMode)
                else {dfx.DirectAdjoint: "bounded"}.get(type(adjoint))
            )
            if kind is not None and isinstance(solver, dfx.AbstractRungeKutta):
                if solver.scan_kind is None:
                    solver = eqx.tree_at(
                        lambda s: s.scan_kind, solver, kind, is_leaf=lambda x: x is None
                    )
            solver = _ProjectedSolverAD(solver)
        else:
            solver = ProjectedSolver(solver)
        save_fn = lambda t, y, args: args.model.project(y)
    meter = (
        dfx.TextProgressMeter(minimum_increase=0.05)
        if config.progress
        else dfx.NoProgressMeter()
    )
    return dfx.diffeqsolve(
        dfx.ODETerm(scene_vector_field),
        solver,
        t0=scene.t0,
        t1=scene.t1,
        dt0=dt0,
        y0=scene.y0,
        args=scene,
        saveat=saveat(save_fn),
        stepsize_controller=controller,
        max_steps=config.max_steps,
        throw=False,
        progress_meter=meter,
        adjoint=adjoint,
    )


def solve(scene: Scene, config: SolveConfig, ts=None) -> Trajectory:
    """Integrate `scene`: the one solve behind `simulate`, `fit` and `sweep`.

    Usable inside `jax.grad`, `jax.vmap` and `jit`: no check here looks at array
    values (the scene may be traced); `config` was checked when it was built. `ts`
    defaults to `config.n_save` points over the span. A failed solve does not raise:
    the Trajectory's `result` says why, with the data up to the failure.
    """
    if ts is None:
        ts = jnp.linspace(scene.t0, scene.t1, config.n_save)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    sol = _diffeqsolve(
        scene,
        config,
        lambda fn: dfx.SaveAt(ts=ts) if fn is None else dfx.SaveAt(ts=ts, fn=fn),
    )
    return Trajectory.from_solution(ts, sol.ys, sol.result, sol.stats, scene)


_solve = cpu_jit(solve)


def _solve_fields(scene, config, ts):
    """`solve`'s Trajectory as a dict of arrays (a saved program's output)."""
    traj = solve(scene, config, ts)
    fields = {f.name: getattr(traj, f.name) for f in dataclasses.fields(traj)}
    return fields | {"result": result_code(traj.result)}


def _solve_saved(scene, config, ts) -> Trajectory:
    """`_solve` through a saved program where one can be saved (see
    `jaxstring._programs`)."""
    fields = _programs.call(_solve_fields, scene, config, ts)
    if fields is None:
        return _solve(scene, config, ts)
    return Trajectory(**(fields | {"result": result_from_code(fields["result"])}))


def _save_times(scene: Scene, ts, n_save):
    """The save times of `simulate` and `sweep`: `ts` checked against the scene's
    span, or `n_save` (an int >= 2) points over it; float64."""
    if ts is None:
        check_int("n_save", n_save, 2)
        ts = jnp.linspace(scene.t0, scene.t1, n_save)
    else:
        check_times("ts", ts, scene.t0, scene.t1)
    return jnp.asarray(ts, dtype=jnp.float64)


def simulate(
    scene: Scene,
    solver="kvaerno5",
    *,
    rtol: float = 1e-6,
    atol: float = 1e-6,
    ts=None,
    n_save: int = 201,
    dt0=None,
    newton_rtol=None,
    newton_atol=None,
    max_steps: int = 200_000,
    progress: bool = False,
    project: bool = True,
    accuracy: str | None = None,
    step_control: str = "auto",
    adjoint=None,
) -> Trajectory:
    """Integrate a scene and return its Trajectory.

    **Arguments:**

    - `scene`: a `Scene` (see `jaxstring.scenes`).
    - `solver`: a name from `jaxstring.SOLVERS` (each with a one-line description
      there) or any `diffrax.AbstractSolver` instance. Adaptive implicit:
      `"kvaerno3"`, `"kvaerno4"`, `"kvaerno5"` (default), `"implicit_euler"`,
      `"rodas5p"` (Rosenbrock, one Jacobian per step: the fastest here on stiff
      strings). Fixed step `dt0`: `"implicit_euler_fixed"`, `"theta"`/`"trapezoid"`
      (theta = 1/2), `"newmark"`; other theta: pass `jaxstring.ThetaMethod(theta)`.
      Explicit: `"tsit5"`, `"dopri5"`.
    - `rtol`, `atol`: error tolerances of the step-size controller (> 0).
    - `ts`: save times, s (default: `n_save` equally spaced points over the span).
    - `dt0`: initial step, s (default: chosen by the controller); the step of a
      fixed-step solver (default 0.005 s, the paper's).
    - `newton_rtol`, `newton_atol`: tolerances of the stage Newton iteration
      (default: `rtol`, `atol`).
    - `max_steps`: limit on the number of steps.
    - `progress`: print a text progress meter.
    - `accuracy`: `"draft"`, `"balanced"` or `"precise"` -- a preset of solver and
      tolerances for the scene's system (each pendulum formulation, the tether, any
      other model), measured in `experiments/race_strongest.py --presets` (see
      `jaxstring.ACCURACY_PRESETS` for the measured error and time of each); it
      replaces `solver`, `rtol` and `atol`.
    - `project`: for models with a constraint manifold (the Cartesian-tangent
      string), project the state onto it after every step and at the save times
      (default True); False integrates the raw constrained equations, to show drift.
    - `step_control`: `"auto"` (default), `"pid"` or `"newton-limited"`: the
      adaptive step-size controller. `"auto"` is diffrax's `PIDController` (for
      Rodas5P with the step growth capped at 3x per step), except
      for the Newton-stage solvers (Kvaerno, adaptive implicit Euler), which get
      `NewtonLimitedController`: a PID controller that, after a failed stage
      Newton iteration, halves the step and caps it just below the failed size
      (1.6-2.4x faster Kvaerno5 on stiff strings).
    - `adjoint`: how `jax.grad` differentiates through the solve: `"recursive"`
      (default: diffrax's checkpointed reverse mode), `"direct"`, `"backsolve"`,
      `"forward"` (forward mode: best for a few parameters), or a diffrax adjoint.

    Implicit solvers build the Newton matrix from an autodiff (forward-mode)
    Jacobian of the vector field. A failed solve does not raise: the returned
    `Trajectory` has `ok == False`, a `status` message, and the data up to the
    failure (`n_valid` saved rows; later rows are NaN).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if accuracy is not None:
        check_choice("accuracy", accuracy, tuple(ACCURACY_PRESETS))
        preset = resolve_preset(accuracy, scene.model)
        solver, rtol, atol = preset["solver"], preset["rtol"], preset["atol"]
    check_solver(solver)
    check_positive("rtol", rtol)
    check_positive("atol", atol)
    check_int("max_steps", max_steps, 1)
    check_choice("step_control", step_control, STEP_CONTROLS)
    if dt0 is not None:
        check_positive("dt0", dt0, "s")
    if newton_rtol is not None:
        check_positive("newton_rtol", newton_rtol)
    if newton_atol is not None:
        check_positive("newton_atol", newton_atol)
    check_bool("project", project)
    check_bool("progress", progress)
    ts = _save_times(scene, ts, n_save)
    f64 = lambda x: None if x is None else jnp.asarray(x, dtype=jnp.float64)
    config = SolveConfig(
        solver=solver,
        rtol=f64(rtol),
        atol=f64(atol),
        n_save=max(2, int(np.shape(ts)[0])),
        dt0=f64(dt0),
        newton_rtol=f64(newton_rtol),
        newton_atol=f64(newton_atol),
        max_steps=max_steps,
        project=bool(project),
        adjoint=None if adjoint is None else make_adjoint(adjoint),
        step_control=step_control,
        progress=bool(progress),
    )
    if not config.progress and _programs.usable((scene, config, ts)):
        return _solve_saved(scene, config, ts)
    return _solve(scene, config, ts)
