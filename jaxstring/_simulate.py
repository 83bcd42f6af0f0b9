"""simulate(scene, ...) -> Trajectory."""

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np

from ._jit import cpu_jit
from ._scene import Scene, scene_vector_field
from ._solvers.presets import ACCURACY_PRESETS
from ._solvers.projected import ProjectedSolver
from ._solvers.registry import build_solver, check_solver, is_adaptive
from ._solvers.step_size import STEP_CONTROLS, make_controller
from ._trajectory import Trajectory
from ._validate import check_choice, check_int, check_positive, is_concrete


def observables(scene: Scene, ts, ys):
    """Derived observables of saved states `ys` (leading axis: time)."""
    return jax.vmap(lambda t, y: scene.model.observables(t, y, scene.effects))(ts, ys)


@cpu_jit
def _solve(
    scene,
    ts,
    rtol,
    atol,
    dt0,
    newton_rtol,
    newton_atol,
    solver,
    adaptive,
    max_steps,
    progress,
    project,
    step_control="auto",
):
    term = dfx.ODETerm(scene_vector_field)
    dfx_solver = build_solver(solver, newton_rtol, newton_atol, scene)
    if project and scene.model.projects:
        dfx_solver = ProjectedSolver(dfx_solver)
        saveat = dfx.SaveAt(ts=ts, fn=lambda t, y, args: args.model.project(y))
    else:
        saveat = dfx.SaveAt(ts=ts)
    controller = make_controller(solver, rtol, atol, adaptive, step_control)
    meter = (
        dfx.TextProgressMeter(minimum_increase=0.05)
        if progress
        else (dfx.NoProgressMeter())
    )
    sol = dfx.diffeqsolve(
        term,
        dfx_solver,
        t0=scene.t0,
        t1=scene.t1,
        dt0=dt0,
        y0=scene.y0,
        args=scene,
        saveat=saveat,
        stepsize_controller=controller,
        max_steps=max_steps,
        throw=False,
        progress_meter=meter,
    )
    ys = sol.ys
    # States after a failure are inf in diffrax's output: evaluate observables on
    # finite states only, and mark how far the run got.
    finite = jnp.all(jnp.isfinite(ys.reshape(ys.shape[0], -1)), axis=1)
    n_valid = jnp.sum(jnp.cumprod(finite))
    safe_ys = jnp.where(finite.reshape((-1,) + (1,) * (ys.ndim - 1)), ys, scene.y0)
    obs = observables(scene, ts, safe_ys)

    def mask(x):
        m = finite.reshape((-1,) + (1,) * (x.ndim - 1))
        return jnp.where(m, x, jnp.nan)

    stats = {
        key: sol.stats[key]
        for key in (
            "num_steps",
            "num_accepted_steps",
            "num_rejected_steps",
            "max_steps",
        )
    }
    t_end = jnp.where(n_valid > 0, ts[jnp.maximum(n_valid - 1, 0)], scene.t0)
    return Trajectory(
        ts=ts,
        ys=ys,
        obs=jax.tree_util.tree_map(mask, obs),
        result=sol.result,
        stats=stats,
        t_end=t_end,
        n_valid=n_valid,
    )


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
      tolerances measured in `experiments/work_precision.py` (see
      `jaxstring.ACCURACY_PRESETS` for the measured error and time of each); it
      replaces `solver`, `rtol` and `atol`.
    - `project`: for models with a constraint manifold (the Cartesian-tangent
      string), project the state onto it after every step and at the save times
      (default True); False integrates the raw constrained equations, to show drift.
    - `step_control`: `"auto"` (default), `"pid"` or `"newton-limited"`: the
      adaptive step-size controller. `"auto"` is diffrax's `PIDController`, except
      for the Newton-stage solvers (Kvaerno, adaptive implicit Euler), which get
      `NewtonLimitedController`: a PID controller that, after a failed stage
      Newton iteration, halves the step and caps it just below the failed size
      (see `jaxstring._controller`; 1.6-2.4x faster Kvaerno5 on stiff strings).

    Implicit solvers build the Newton matrix from an autodiff (forward-mode)
    Jacobian of the vector field. A failed solve does not raise: the returned
    `Trajectory` has `ok == False`, a `status` message, and the data up to the
    failure (`n_valid` saved rows; later rows are NaN).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if accuracy is not None:
        check_choice("accuracy", accuracy, tuple(ACCURACY_PRESETS))
        preset = ACCURACY_PRESETS[accuracy]
        solver, rtol, atol = preset["solver"], preset["rtol"], preset["atol"]
    check_solver(solver)
    check_positive("rtol", rtol)
    check_positive("atol", atol)
    check_int("max_steps", max_steps, 1)
    check_choice("step_control", step_control, STEP_CONTROLS)
    adaptive = is_adaptive(solver)
    if not adaptive and dt0 is None:
        dt0 = 0.005
    if dt0 is not None:
        check_positive("dt0", dt0, "s")
        dt0 = jnp.asarray(dt0, dtype=jnp.float64)
    if ts is None:
        check_int("n_save", n_save, 2)
        ts = jnp.linspace(scene.t0, scene.t1, n_save)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    if is_concrete(ts):
        tsn = np.asarray(ts)
        if tsn.ndim != 1 or np.any(np.diff(tsn) < 0):
            raise ValueError("`ts` must be a 1-d array of increasing times.")
        span_known = is_concrete(scene.t0) and is_concrete(scene.t1)
        if span_known and (tsn[0] < float(scene.t0) or tsn[-1] > float(scene.t1)):
            raise ValueError("`ts` must lie inside [scene.t0, scene.t1].")
    nr = rtol if newton_rtol is None else newton_rtol
    na = atol if newton_atol is None else newton_atol
    check_positive("newton_rtol", nr)
    check_positive("newton_atol", na)
    f64 = lambda x: jnp.asarray(x, dtype=jnp.float64)
    return _solve(
        scene,
        ts,
        f64(rtol),
        f64(atol),
        dt0,
        f64(nr),
        f64(na),
        solver,
        adaptive,
        max_steps,
        progress,
        bool(project),
        step_control,
    )
