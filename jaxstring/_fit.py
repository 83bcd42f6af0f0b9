"""fit: gradient-based identification and tuning of scene parameters with optax.

The same scene that `simulate` integrates is the model that is fitted: chosen array
leaves of the scene (a stiffness, a damping constant, a drag coefficient, a
controller gain) are the unknowns, every other leaf stays frozen. The split is an
`eqx.partition` with a boolean filter spec (equinox FAQ, "frozen layers"); one
optimiser step -- simulate, loss, gradient, optax update -- is one compiled call
(`cpu_jit`).

Positive parameters are optimised as log p: the update is then relative (a step of
0.05 changes EA = 1e6 N and alpha = 0.01 s by the same 5 %), and p can never cross 0.

Gradients go through the solver ("discretise then optimise"): diffrax's
`RecursiveCheckpointAdjoint` by default, with as many checkpoints as the forward run
takes steps (`checkpoints="auto"`), so the backward pass recomputes each step about
once. `DirectAdjoint`, `BacksolveAdjoint` and forward mode (`ForwardMode`, best for
one or two parameters and for Jacobians of residuals) can be chosen by name.
"""

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import diffrax as dfx
import equinox as eqx
import jax
import jax.flatten_util as jfu
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import optax

from . import _distribute
from ._adjoints import SensitivityAdjoint
from ._blas import single_blas_thread
from ._integrate import solve
from ._jit import cpu_jit
from ._parameters import filter_spec, resolve
from ._presets import solver_for
from ._scene import Scene
from ._sensitivity import derivatives
from ._solve_config import SolveConfig, solve_config
from ._validate import check_int, check_nonnegative, check_positive


# --------------------------------------------------------------------------------------
# A solve that can be differentiated, with a choice of adjoint


# --------------------------------------------------------------------------------------
# fit


class FitResult(eqx.Module):
    """What `fit` returns.

    **Fields:**

    - `scene`: the scene with the fitted parameter values.
    - `losses`: loss at each step (before its update), NumPy array `(steps,)`.
    - `grad_norm`: 2-norm of the gradient at the last evaluated point, with respect to
      the optimised variables (log p for positive parameters: a relative sensitivity).
    - `params`: dict label -> NumPy array of the parameter's values along the run.
    - `names`: the labels of the fitted parameters, in the order given.
    - `converged`: whether a stopping test (`gtol`) was met.
    - `message`: why the run stopped.
    - `compile_time`, `run_time`: seconds (the first step includes compilation).
    - `processes`: worker processes of this host that evaluated the experiments
      (1: this process; 0: a user's executor).
    """

    scene: Scene
    losses: np.ndarray
    grad_norm: float
    params: dict
    names: tuple
    converged: bool
    message: str
    compile_time: float
    run_time: float
    processes: int = 1

    def values(self) -> dict:
        """Fitted values, label -> float."""
        return {n: float(v[-1]) for n, v in self.params.items()}


class Misfit(eqx.Module):
    """The residual `model - data` of a trajectory, for `fit`, `least_squares` and
    `gauss_newton`: `Misfit(data)(traj, scene)` is `traj.end_mass - data`.

    **Fields:** `data`, the measurements at the saved times `ts` (an array leaf,
    traced: one compiled fit serves every data set of the same shape);
    `observable`, the name of a trajectory observable (`"end_mass"`, or a key of
    `traj.obs` such as `"positions"`, `"heading"`); `nodes`, indices along the
    observable's second axis to compare (None: all of it).
    """

    data: Any
    observable: str = eqx.field(static=True, default="end_mass")
    nodes: tuple | None = eqx.field(static=True, default=None)

    def __call__(self, traj, scene):
        del scene
        x = getattr(traj, self.observable)
        if self.nodes is not None:
            x = x[:, list(self.nodes)]
        return x - self.data


def _strongly_typed(tree, device):
    """`tree` with every array strongly typed (of its dtype) and committed to
    `device`."""

    def strong(x):
        if jax.typeof(x).weak_type:
            x = jax.lax.convert_element_type(x, x.dtype)
        return jax.device_put(x, device)

    dynamic, static = eqx.partition(tree, eqx.is_array)
    return eqx.combine(jtu.tree_map(strong, dynamic), static)


def _to_theta(diff, pos):
    return jtu.tree_map(lambda x, p: jnp.log(x) if p else x, diff, pos)


def _from_theta(theta, pos):
    return jtu.tree_map(lambda x, p: jnp.exp(x) if p else x, theta, pos)


def _stacked(theta, getters):
    """The fitted parameters of `theta` (in the optimised variables) as a vector."""
    return jnp.stack([jnp.asarray(g(theta), jnp.float64) for g in getters])


def _as_theta(theta, getters, values):
    """`values` (one per getter) as a tree like `theta`, zero elsewhere: a gradient
    in the fit's variables."""
    zero = jtu.tree_map(jnp.zeros_like, theta)
    return eqx.tree_at(lambda t: [g(t) for g in getters], zero, list(values))


class _Experiments(eqx.Module):
    """Several experiments fitted together in this process: each its own
    parameter tree (in the optimised variables), positivity flags, frozen part
    and getters; the fit's parameters are those of the first, whose values every
    experiment takes. The loss is the sum of the experiments' losses."""

    templates: tuple
    frozens: tuple
    poss: tuple = eqx.field(static=True)
    getters: tuple = eqx.field(static=True)

    def each(self, theta):
        """(theta, pos, frozen) of every experiment at the fit's `theta`."""
        values = [g(theta) for g in self.getters[0]]
        for template, pos, frozen, getters in zip(
            self.templates, self.poss, self.frozens, self.getters
        ):
            th = eqx.tree_at(lambda t: [g(t) for g in getters], template, values)
            yield th, pos, frozen

    def gather(self, theta, grads):
        """The sum of the experiments' gradients `grads` (each in its own
        parameter tree) as a gradient in the fit's `theta`."""
        total = [
            sum(g(grad) for g, grad in zip(gs, grads)) for gs in zip(*self.getters)
        ]
        return _as_theta(theta, self.getters[0], total)


class _RemoteExperiments(eqx.Module):
    """Several experiments fitted together, each evaluated (loss and gradient) in a
    worker process: `token` names the fit's `ExperimentPrograms`
    (`_distribute.register`)."""

    token: Any
    getters: tuple = eqx.field(static=True)

    def loss(self):
        """The loss of all experiments as a function of theta, with its gradient
        from the same evaluation in the workers."""

        def evaluate(theta):
            x = _stacked(theta, self.getters)
            shapes = (
                jax.ShapeDtypeStruct((), jnp.float64),
                jax.ShapeDtypeStruct(x.shape, jnp.float64),
            )
            return jax.pure_callback(
                _distribute.evaluate_registered,
                shapes,
                self.token,
                x,
                vmap_method="sequential",
            )

        def value_and_grad(theta):
            value, g = evaluate(theta)
            return value, _as_theta(theta, self.getters, list(g))

        return _with_gradient(lambda theta: evaluate(theta)[0], value_and_grad)


def _objective(theta, pos, frozen, loss_fn, config, simulate, ts):
    if isinstance(frozen, _Experiments):
        return sum(
            _objective(th, p, f, loss_fn, config, simulate, ts)
            for th, p, f in frozen.each(theta)
        )
    scene = eqx.combine(_from_theta(theta, pos), frozen)
    if simulate:
        return loss_fn(solve(scene, config, ts), scene)
    return loss_fn(scene)


def _with_gradient(f, value_and_grad):
    """`f` with a reverse-mode rule from `value_and_grad(theta) -> (value, grad)`:
    lets reverse-mode callers (`jax.grad`, optax line searches) use a gradient
    computed another way (forward mode, sensitivities)."""

    @jax.custom_vjp
    def h(theta):
        return f(theta)

    def bwd(grad, ct):
        return (jtu.tree_map(lambda x: ct * x, grad),)

    h.defvjp(value_and_grad, bwd)
    return h


def _forward_mode(f):
    """`f` whose gradient is computed in forward mode: one JVP per optimised
    scalar, sharing the primal solve (diffrax's `ForwardMode`)."""

    def value_and_grad(theta):
        flat, unravel = jfu.ravel_pytree(theta)
        g = lambda x: f(unravel(x))
        value, grad = jax.vmap(lambda v: jax.jvp(g, (flat,), (v,)), out_axes=(None, 0))(
            jnp.eye(flat.size, dtype=flat.dtype)
        )
        return value, unravel(grad)

    return _with_gradient(f, value_and_grad)


def _sensitivity_value_and_grad(theta, pos, frozen, loss_fn, config, ts):
    """Loss and gradient from the sensitivities integrated with the state
    (`jaxstring._sensitivity.derivatives`)."""
    if isinstance(frozen, _Experiments):
        parts = [
            _sensitivity_value_and_grad(th, p, f, loss_fn, config, ts)
            for th, p, f in frozen.each(theta)
        ]
        value = sum(v for v, _ in parts)
        return value, frozen.gather(theta, [g for _, g in parts])
    flat, unravel = jfu.ravel_pytree(theta)
    scene_of = lambda x: eqx.combine(_from_theta(unravel(x), pos), frozen)
    is_log = jfu.ravel_pytree(
        jtu.tree_map(lambda x, p: jnp.full(jnp.shape(x), p), theta, pos)
    )[0]
    value, grad = derivatives(scene_of, flat, is_log, config, ts, loss_fn)
    return value, unravel(grad)


def _value_and_grad(theta, pos, frozen, loss_fn, config, simulate, ts):
    f = lambda th: _objective(th, pos, frozen, loss_fn, config, simulate, ts)
    adjoint = config.adjoint_for("gradient")
    if isinstance(frozen, _RemoteExperiments):
        f = frozen.loss()
    elif isinstance(adjoint, SensitivityAdjoint):
        f = _with_gradient(
            f,
            lambda th: _sensitivity_value_and_grad(
                th, pos, frozen, loss_fn, config, ts
            ),
        )
    elif isinstance(adjoint, dfx.ForwardMode):
        f = _forward_mode(f)
    value, grad = jax.value_and_grad(f)(theta)
    return value, grad, f


def _experiment_loss(x, template, frozen, pos, getters, loss_fn, config, ts):
    """One experiment's loss and its gradient d loss / d x at the fit's
    parameters `x` (in the optimised variables, stacked): the program a worker
    runs."""
    values = [x[i] for i in range(x.shape[0])]
    theta = eqx.tree_at(lambda t: [g(t) for g in getters], template, values)
    value, grad, _ = _value_and_grad(theta, pos, frozen, loss_fn, config, True, ts)
    return value, jnp.stack([jnp.asarray(g(grad), jnp.float64) for g in getters])


def _summed(outs):
    """The sum of the experiments' losses and gradients (`_experiment_loss`)."""
    value = sum(float(out[0]) for out in outs)
    grad = sum(np.asarray(out[1], np.float64) for out in outs)
    return np.asarray(value, np.float64), grad


def _experiments(scenes, loss_fn, params, positive, config, processes, executor):
    """The fit's own parameters and the form of its experiments: `frozen` is the
    first scene's frozen part (one scene in this process), an `_Experiments`
    (several in this process) or a `_RemoteExperiments` (in worker processes);
    with the evaluations of the workers (or None) and their number."""
    getters, theta, pos, frozen, cfg, ts = _setup(
        scenes[0], loss_fn, params, positive, True, config, count_steps=True
    )
    parts = [(theta, frozen, pos, tuple(getters))]
    for sc in scenes[1:]:
        g, th, p, f, c, _ = _setup(
            sc, loss_fn, params, positive, True, config, count_steps=True
        )
        parts.append((th, f, p, tuple(g)))
        if isinstance(c.checkpoints, int) and isinstance(cfg.checkpoints, int):
            cfg = cfg.replace(checkpoints=max(c.checkpoints, cfg.checkpoints))
    workers = _distribute.experiment_workers(
        processes, executor, len(scenes), cfg.on_cpu()
    )
    evaluations = None
    if executor is not None or workers > 1 or _distribute.distributed():
        x0 = _stacked(theta, getters)
        args = [(x0, *p, loss_fn, cfg, ts) for p in parts]
        evaluations = _distribute.ExperimentPrograms(
            _experiment_loss, args, executor, workers, _summed
        )
        token = _distribute.register(evaluations)
        frozen = _RemoteExperiments(jnp.asarray(token), tuple(getters))
    elif len(scenes) > 1:
        frozen = _Experiments(
            templates=tuple(p[0] for p in parts),
            frozens=tuple(p[1] for p in parts),
            poss=tuple(p[2] for p in parts),
            getters=tuple(p[3] for p in parts),
        )
    return getters, theta, pos, parts[0][1], frozen, cfg, ts, evaluations, workers


@cpu_jit
def _make_step(theta, opt_state, pos, frozen, loss_fn, optimizer, config, simulate, ts):
    value, grad, f = _value_and_grad(theta, pos, frozen, loss_fn, config, simulate, ts)
    updates, new_state = optimizer.update(
        grad, opt_state, theta, value=value, grad=grad, value_fn=f
    )
    new_theta = optax.apply_updates(theta, updates)
    gnorm = optax.global_norm(grad)
    good = jnp.isfinite(value) & jnp.isfinite(gnorm)
    # A failed solve (NaN loss) leaves the parameters where they were.
    keep = lambda new, old: jtu.tree_map(lambda a, b: jnp.where(good, a, b), new, old)
    new_theta = keep(new_theta, theta)
    new_state = keep(new_state, opt_state)
    return new_theta, new_state, value, gnorm


def _count_steps(scene, config, ts) -> int:
    traj = solve(scene, config, ts, adjoint=dfx.RecursiveCheckpointAdjoint())
    return int(traj.stats["num_steps"])


def resolve_params(scene, params, positive):
    """Getters of the named parameters (`resolve` each) and one `positive` flag
    per parameter; ValueError for none, a leaf named twice or a `positive` of
    the wrong length."""
    if isinstance(params, str) or callable(params):
        params = [params]
    if len(params) == 0:
        raise ValueError("`params` must name at least one parameter to fit.")
    getters = [resolve(scene, p) for p in params]
    if len({g.path for g in getters}) != len(getters):
        raise ValueError("`params` names the same leaf twice.")
    if isinstance(positive, bool):
        positive = [positive] * len(getters)
    positive = [bool(p) for p in positive]
    if len(positive) != len(getters):
        raise ValueError(
            f"`positive` must be one bool or {len(getters)} bools (one per parameter)."
        )
    return getters, positive


def identify_config(scene, config, options, derivative, simulate=True):
    """The `SolveConfig` of an identification solve of `scene` ("identify"
    defaults, `config`, the shortcuts `options`), checked against the scene and
    against the derivative it serves ("gradient" or "jacobian")."""
    config = solver_for(solve_config("identify", config, **options), scene)
    config.check_scene(scene)
    if isinstance(config.adjoint_for(derivative), SensitivityAdjoint) and not simulate:
        raise ValueError(
            "`adjoint='sensitivity'` integrates the scene's sensitivities itself "
            "and needs simulate=True (a loss that simulates itself: use "
            "'forward' or 'recursive')."
        )
    return config


def _setup(scene, loss_fn, params, positive, simulate, config, count_steps):
    """Check the arguments of `fit`/`value_and_grad`; split the scene. With
    `count_steps`, `checkpoints="auto"` of a reverse-mode gradient becomes the
    number of steps of one forward solve (plus a margin); without, diffrax's
    log-depth recursion."""
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if not callable(loss_fn):
        raise ValueError("`loss_fn` must be callable: loss_fn(traj, scene) -> scalar.")
    getters, positive = resolve_params(scene, params, positive)
    for g, p in zip(getters, positive):
        x = np.asarray(g(scene))
        if p and (not np.all(np.isfinite(x)) or np.any(x <= 0)):
            raise ValueError(
                f"parameter {g.label!r} = {x} is fitted as positive (log p) and must "
                "be > 0; give a positive initial value or positive=False for it."
            )
    ts = config.ts
    config = config.replace(ts=None)
    if config.checkpoints == "auto":
        n = None
        adj = config.adjoint_for("gradient")
        if simulate and count_steps and type(adj) is dfx.RecursiveCheckpointAdjoint:
            n = max(16, int(1.1 * _count_steps(scene, config, ts)) + 8)
        config = config.replace(checkpoints=n)
    spec = filter_spec(scene, getters)
    diff, frozen = eqx.partition(scene, spec)
    pos_tree = eqx.tree_at(lambda s: [g(s) for g in getters], spec, replace=positive)
    # `pos` has the structure of `diff`: bools at the chosen leaves, None elsewhere.
    pos, _ = eqx.partition(pos_tree, spec)
    return getters, _to_theta(diff, pos), pos, frozen, config, ts


@cpu_jit
def _jit_value_and_grad(theta, pos, frozen, loss_fn, config, simulate, ts):
    value, grad, _ = _value_and_grad(theta, pos, frozen, loss_fn, config, simulate, ts)
    return value, grad


@single_blas_thread
def value_and_grad(
    scene: Scene,
    loss_fn: Callable,
    params: Sequence,
    *,
    simulate: bool = True,
    config: SolveConfig | None = None,
    **options,
) -> tuple[float, dict]:
    """Loss and its gradient d loss / d p with respect to chosen parameters, in the
    parameters' own units, computed as `fit` computes them.

    Arguments as for `fit`: `config` (default: `SolveConfig.default("identify")`)
    and its fields as shortcuts (`rtol`, `ts`, `adjoint`, ...). With
    `checkpoints="auto"` a single gradient uses diffrax's log-depth recursion
    (`fit` counts the steps of one forward solve instead).

    **Returns:** `(loss, {label: gradient})`.
    """
    config = identify_config(scene, config, options, "gradient", simulate)
    getters, theta, pos, frozen, config, ts = _setup(
        scene, loss_fn, params, False, simulate, config, count_steps=False
    )
    theta, frozen, config, ts = config.placed((theta, frozen, config, ts))
    value, grad = _jit_value_and_grad(theta, pos, frozen, loss_fn, config, simulate, ts)
    return float(value), {g.label: np.asarray(g(grad)) for g in getters}


@single_blas_thread
def fit(
    scene: Scene | Sequence[Scene],
    loss_fn: Callable,
    params: Sequence,
    *,
    steps: int = 100,
    optimizer: optax.GradientTransformation | None = None,
    learning_rate: float = 0.05,
    positive: bool | Sequence[bool] = True,
    simulate: bool = True,
    gtol: float | None = None,
    print_every: int | None = 10,
    callback: Callable | None = None,
    processes="auto",
    executor=None,
    config: SolveConfig | None = None,
    **options,
) -> FitResult:
    """Minimise `loss_fn` over chosen parameter leaves of `scene` with optax.

    **Arguments:**

    - `scene`: the starting scene; its values of `params` are the initial guess.
      Or a list of scenes: several experiments sharing the parameters (each must
      hold every named parameter; the first one's values are the initial guess),
      whose losses are summed, each experiment solved on its own.
    - `loss_fn`: `loss_fn(traj, scene) -> scalar`, with `traj` the scene's
      `Trajectory` (saved at `ts`); with `simulate=False`, `loss_fn(scene) -> scalar`
      and the function simulates itself (several scenes, windows, ...: use
      `jaxstring._fit.solve` or `jaxstring.simulate` inside). Data it closes over is
      compiled in as constants; an `eqx.Module` loss with array fields is traced.
    - `params`: the leaves to fit, each a name (`"alpha"`, `"EA"`,
      `"KelvinVoigt.alpha"`, `"model.EA"`) or a callable (`lambda s: s.model.EA`).
    - `steps`: number of optimiser steps.
    - `optimizer`: any optax transformation (default `optax.adam(learning_rate)`);
      transformations that take extra arguments (`optax.lbfgs`) get `value`, `grad`
      and `value_fn`.
    - `positive`: optimise log p (one bool for all parameters or one per parameter).
    - `config`: the `SolveConfig` of the solves (default:
      `SolveConfig.default("identify")`); `options`: its fields as shortcuts
      (`solver`, `rtol`, `atol`, `ts`, `n_save`, `dt0`, `max_steps`, `project`,
      ...). Its `adjoint` says how the gradient goes through the solve:
      `"auto"`/`"recursive"` (diffrax's checkpointed reverse mode; with
      `checkpoints="auto"`, as many checkpoints as one forward solve takes steps,
      about one recomputation per step in the backward pass), `"direct"` (small
      `max_steps` only), `"backsolve"` (continuous adjoint: gradients accurate to
      the solver tolerance only), `"forward"` (one JVP per parameter: best for one
      or two parameters), `"sensitivity"` (forward sensitivities integrated with
      the state under the same error control, so the gradient is accurate where
      the steps chosen for the state alone do not resolve it, e.g. through
      slack-and-snap motions; not for projecting models) or a diffrax adjoint.
    - `gtol`: stop when the gradient norm (in the optimised variables) falls below.
    - `print_every`: print step, loss, gradient norm and values every this many
      steps (None: silent).
    - `callback`: called as `callback(step, loss, scene)` after every step.
    - `processes`: `"auto"` (default: with two or more experiments solved on a CPU,
      as they are under `device="auto"` also on a GPU host, one worker process per
      experiment up to the host's cores; else this process alone), or the number
      of worker processes. With workers, each step sends the current parameters
      to them; each experiment's loss and gradient come from one program per
      experiment, traced once in this process and run in jaxstring's own pool of
      spawned processes (the pool of `sweep` and `least_squares`), and the
      optimiser's step is taken here.
      In a `jax.distributed` job they are split over its processes, as
      `least_squares` splits them, and every process takes the same steps.
    - `executor`: any `concurrent.futures.Executor` whose workers can import
      jaxstring (a `ProcessPoolExecutor`, a Dask cluster's executor) to evaluate
      the experiments instead. A worker that dies is replaced and its experiment
      evaluated again; one whose evaluation fails twice stops the fit with a
      message naming the experiment.

    **Returns:** a `FitResult` (fitted scene -- the first experiment's --, loss
    history, final gradient norm, parameter history).
    """
    # Checked before `_setup`, which with checkpoints="auto" runs a solve.
    check_int("steps", steps, 1)
    if optimizer is None:
        check_positive("learning_rate", learning_rate)
    elif not isinstance(optimizer, optax.GradientTransformation):
        raise ValueError(
            "`optimizer` must be an optax GradientTransformation (e.g. "
            f"optax.adam(1e-2)); got {optimizer!r}."
        )
    if gtol is not None:
        check_nonnegative("gtol", gtol)
    if print_every is not None:
        check_int("print_every", print_every, 0)
    if callback is not None and not callable(callback):
        raise ValueError(
            f"`callback` must be callable as callback(step, loss, scene); got "
            f"{callback!r}."
        )
    scenes = tuple(scene) if isinstance(scene, (list, tuple)) else (scene,)
    if not scenes or not all(isinstance(s, Scene) for s in scenes):
        raise ValueError(
            "`scene` must be a jaxstring Scene or a non-empty list of Scenes."
        )
    _distribute.check_workers(processes, executor)
    several = len(scenes) > 1 or executor is not None or processes != "auto"
    if several and not simulate:
        raise ValueError(
            "`scene`: several experiments, `processes` and `executor` need "
            "simulate=True (a loss that simulates itself takes one scene)."
        )
    config = identify_config(scenes[0], config, options, "gradient", simulate)
    for sc in scenes[1:]:
        config.check_scene(sc)
    evaluations, workers = None, 1
    if several:
        getters, theta, pos, frozen0, frozen, config, ts, evaluations, workers = (
            _experiments(scenes, loss_fn, params, positive, config, processes,
                         executor)
        )  # fmt: skip
    else:
        getters, theta, pos, frozen, config, ts = _setup(
            scene, loss_fn, params, positive, simulate, config, count_steps=True
        )
        frozen0 = frozen
    try:
        return _fit_loop(
            scenes[0], getters, theta, pos, frozen0, frozen, config, ts, loss_fn,
            simulate, steps, optimizer, learning_rate, gtol, print_every, callback,
            evaluations, workers,
        )  # fmt: skip
    finally:
        _distribute.release(evaluations)


def _fit_loop(scene, getters, theta, pos, frozen0, frozen, config, ts, loss_fn,
              simulate, steps, optimizer, learning_rate, gtol, print_every,
              callback, evaluations, workers):  # fmt: skip
    """`fit`'s optimisation loop, its arguments checked and its experiments set up."""
    adj = config.adjoint_for("gradient")
    theta, frozen, config, ts = config.placed((theta, frozen, config, ts))
    if optimizer is None:
        optimizer = optax.adam(learning_rate)
    optimizer = optax.with_extra_args_support(optimizer)
    # Strongly typed and committed to the solve's device, as the step returns
    # them: a weakly typed start (a parameter given as a Python float), or one not
    # committed where data the loss holds are, would compile the step again at its
    # second call.
    device = config.solve_device()
    theta = _strongly_typed(theta, device)
    opt_state = optimizer.init(eqx.filter(theta, eqx.is_inexact_array))
    opt_state = _strongly_typed(opt_state, device)

    labels = tuple(g.label for g in getters)
    history = {n: [] for n in labels}
    losses = []
    gnorm = math.nan
    converged = False
    message = f"reached steps = {steps}"
    compile_time = run_time = 0.0
    current = scene

    def record(sc):
        for n, g in zip(labels, getters):
            history[n].append(np.asarray(g(sc)).copy())

    record(scene)
    if print_every:
        print(f"fit {', '.join(labels)} ({type(adj).__name__}, {steps} steps)")
    for i in range(steps):
        t = time.perf_counter()
        new_theta, opt_state, value, g = _make_step(
            theta, opt_state, pos, frozen, loss_fn, optimizer, config, simulate, ts
        )
        value, gnorm = float(value), float(g)
        elapsed = time.perf_counter() - t
        if i == 0:
            compile_time = elapsed
        else:
            run_time += elapsed
        losses.append(value)
        if not (math.isfinite(value) and math.isfinite(gnorm)):
            message = (
                f"step {i}: loss or gradient not finite (a failed solve?); stopped at "
                "the last good parameters"
            )
            if evaluations is not None and evaluations.failed:
                j, why = min(evaluations.failed.items())
                message = (
                    f"step {i}: the worker evaluating experiment {j} failed twice "
                    f"({why}); stopped at the last good parameters"
                )
            if print_every:
                print(message)
            break
        theta = new_theta
        current = eqx.combine(_from_theta(theta, pos), frozen0)
        record(current)
        if print_every and (i % print_every == 0 or i == steps - 1):
            vals = "  ".join(
                f"{n}={float(np.ravel(history[n][-2])[0]):.6g}" for n in labels
            )
            print(f"  step {i:4d}  loss {value:.6e}  |grad| {gnorm:.3e}  {vals}")
        if callback is not None:
            callback(i, value, current)
        if gtol is not None and gnorm < gtol:
            converged = True
            message = f"|grad| = {gnorm:.3e} < gtol = {gtol:g} at step {i}"
            break
    if print_every:
        print(
            f"  done: {message}; "
            + "  ".join(f"{n}={float(np.ravel(history[n][-1])[0]):.6g}" for n in labels)
        )
    return FitResult(
        scene=current,
        losses=np.asarray(losses),
        grad_norm=gnorm,
        params={n: np.asarray(v) for n, v in history.items()},
        names=labels,
        converged=converged,
        message=message,
        compile_time=compile_time,
        run_time=run_time,
        processes=workers,
    )


# --------------------------------------------------------------------------------------
# Uncertainty of a least-squares fit


@single_blas_thread
def gauss_newton(
    scene: Scene,
    residual_fn: Callable,
    params: Sequence,
    *,
    sigma: float | None = None,
    config: SolveConfig | None = None,
    **options,
) -> dict:
    """Gauss-Newton covariance of a least-squares fit at `scene`.

    With residuals r(p) = `residual_fn(traj, scene)` (any shape, in units of the
    measurement) and measurement noise `sigma` (default: estimated from the residual,
    s^2 = |r|^2 / (n - p)), the Hessian of the negative log-likelihood is
    H = J^T J / sigma^2 and cov(p) = H^{-1}. J is computed in forward mode (one JVP per
    parameter; `adjoint` "auto" or "forward"), or with `adjoint="sensitivity"` from
    the sensitivities integrated beside the state under the solver's error control
    (as for `fit`; not for projecting models). `config` and `options` as for `fit`.

    **Returns:** dict with `names`, `values` (p), `std` (standard deviations, in the
    parameters' units), `cov` (p x p), `J` (residuals x p), `sigma`.
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if not callable(residual_fn):
        raise ValueError("`residual_fn` must be callable: residual_fn(traj, scene).")
    getters, _ = resolve_params(scene, params, False)
    if sigma is not None:
        check_positive("sigma", sigma)
    config = identify_config(scene, config, options, "jacobian")
    check_jacobian_adjoint(config)
    ts = config.save_times(scene.t0, scene.t1)
    config = config.replace(ts=None)
    p0 = jnp.stack([jnp.asarray(g(scene), dtype=jnp.float64) for g in getters])
    p0, scene, config, ts = config.placed((p0, scene, config, ts))
    J, r = _gn_jacobian(p0, scene, tuple(getters), residual_fn, config, ts)
    J, r = np.asarray(J), np.asarray(r)
    n, m = r.size, p0.size
    if sigma is None:
        sigma = math.sqrt(float(r @ r) / max(n - m, 1))
    H = J.T @ J / sigma**2
    cov = np.linalg.inv(H)
    return {
        "names": tuple(g.label for g in getters),
        "values": np.asarray(p0),
        "std": np.sqrt(np.diag(cov)),
        "cov": cov,
        "J": J,
        "sigma": sigma,
    }


def check_jacobian_adjoint(config: SolveConfig) -> None:
    """Refuse an adjoint that cannot give the Jacobian of residuals (the reverse
    modes), naming the valid ones."""
    if not isinstance(config.adjoint_for("jacobian"), dfx.ForwardMode):
        raise ValueError(
            "`adjoint` of a residual Jacobian must be 'auto', 'forward' or "
            f"'sensitivity'; got {config.adjoint!r}."
        )


@cpu_jit
def _gn_jacobian(p0, scene, getters, residual_fn, config, ts):
    def scene_of(p):
        return eqx.tree_at(
            lambda s: [g(s) for g in getters], scene, [p[i] for i in range(len(p))]
        )

    flat_residual = lambda traj, sc: jnp.ravel(residual_fn(traj, sc))
    adjoint = config.adjoint_for("jacobian")
    if isinstance(adjoint, SensitivityAdjoint):
        is_log = jnp.zeros(p0.shape, dtype=bool)
        r, d = derivatives(scene_of, p0, is_log, config, ts, flat_residual)
        return d.T, r

    def res(p):
        sc = scene_of(p)
        return flat_residual(solve(sc, config, ts, adjoint=adjoint), sc)

    return jax.jacfwd(res)(p0), res(p0)
