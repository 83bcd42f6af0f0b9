"""simulate(scene, ...) -> Trajectory."""

from ._blas import single_blas_thread
from ._integrate import solve_compiled
from ._presets import preset, solver_for
from ._scene import Scene
from ._solve_config import SolveConfig, solve_config


@single_blas_thread
def simulate(
    scene: Scene,
    solver=None,
    *,
    config: SolveConfig | None = None,
    accuracy: str | None = None,
    **options,
):
    """Integrate a scene and return its Trajectory.

    **Arguments:**

    - `scene`: a `Scene` (a named scene such as `jaxstring.string_pendulum`, or one
      built by hand).
    - `solver`: a name from `jaxstring.SOLVERS` (each with a one-line description
      there) or any `diffrax.AbstractSolver` instance. Adaptive implicit:
      `"kvaerno3"`, `"kvaerno4"`, `"kvaerno5"` (default), `"implicit_euler"`,
      `"rodas5p"` (Rosenbrock, one Jacobian per step), `"bdf"` (variable order,
      as CVODE). Fixed step `dt0`: `"implicit_euler_fixed"`,
      `"theta"`/`"trapezoid"` (theta = 1/2), `"newmark"`; other theta: pass
      `jaxstring.ThetaMethod(theta)`. Explicit: `"tsit5"`, `"dopri5"`.
    - `config`: a `SolveConfig` (default: `SolveConfig.default("simulate")`).
    - `accuracy`: `"draft"`, `"balanced"` or `"precise"`: the measured preset of
      solver and tolerances for the scene's system (`jaxstring.preset`), in place
      of `config`.
    - `options`: fields of `SolveConfig` replaced in the configuration: `rtol`,
      `atol`, `ts` (save times, s), `n_save`, `dt0`, `newton_rtol`, `newton_atol`,
      `max_steps`, `project`, `adjoint`, `step_control`, `progress`.

    Implicit solvers build the Newton matrix from an autodiff (forward-mode)
    Jacobian of the vector field, banded where the model is a chain. A failed
    solve does not raise: the returned `Trajectory` has `ok == False`, a `status`
    message, and the data up to the failure (`n_valid` saved rows; later rows are
    NaN).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if solver is not None:
        options["solver"] = solver
    if accuracy is not None:
        if config is not None:
            raise ValueError(
                "give `accuracy` or `config`, not both: a preset is a SolveConfig "
                "(jaxstring.preset(accuracy, scene))."
            )
        clash = sorted({"solver", "rtol", "atol"} & set(options))
        if clash:
            raise ValueError(
                f"`accuracy={accuracy!r}` chooses the solver and tolerances; do not "
                f"also give {', '.join(clash)}."
            )
        config = preset(accuracy, scene)
    config = solver_for(solve_config("simulate", config, **options), scene)
    config.check_scene(scene)
    ts = config.save_times(scene.t0, scene.t1)
    scene, solve_config_, ts = config.placed(
        (scene, config.replace_unchecked(ts=None), ts)
    )
    return solve_compiled(scene, solve_config_, ts)
