"""least_squares: identify parameters from measurements by nonlinear least squares.

Minimises the sum of squares of `residual_fn(traj, scene)` over named parameter
leaves with optimistix's Levenberg-Marquardt. Each iteration takes one forward solve
and the Jacobian of the residuals in forward mode (one JVP per parameter, through the
solver: diffrax `ForwardMode`); for a few parameters that is far cheaper than the
reverse-mode gradients of a first-order optimiser (`fit`), and LM converges in
ten-odd iterations where Adam needs hundreds of steps. With `adjoint="sensitivity"`
the Jacobian comes instead from the sensitivities integrated beside the state under
the solver's error control (`jaxstring._sensitivity`), for motions whose derivative
the state's own steps do not resolve.

Positive parameters are fitted as log p (relative steps; p never crosses 0). At the
optimum the Gauss-Newton covariance cov(p) = sigma^2 (J^T J)^{-1} gives the standard
deviations, with sigma given or estimated from the residual, s^2 = |r|^2 / (m - n).

Several experiments can be evaluated in worker processes (`processes`, `executor`;
the machinery of `sweep`: `jaxstring._distribute`). Each experiment's residuals and
their Jacobian are one exported program per experiment structure; the compiled
Levenberg-Marquardt iteration stays in the calling process and reaches the workers
through a host callback (`jax.pure_callback`) whose JVP is the Jacobian the workers
return: the iteration is the one-process iteration, fed with the workers'
residuals and Jacobians.
"""

import functools
import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from . import _distribute
from ._adjoints import SensitivityAdjoint
from ._blas import single_blas_thread
from ._fit import check_jacobian_adjoint, identify_config, resolve, resolve_params
from ._integrate import solve
from ._jit import cpu_jit
from ._scene import Scene
from ._sensitivity import derivatives
from ._solve_config import SolveConfig
from ._validate import check_int, check_positive, show


class LeastSquaresResult(eqx.Module):
    """What `least_squares` returns.

    **Fields:**

    - `scene`: the (first) scene with the fitted values; `scenes`: all of them.
    - `values`: dict label -> fitted value. `std`: dict label -> standard deviation
      (Gauss-Newton, in the parameter's units). `cov`: `(n, n)` covariance.
    - `names`: the labels of the parameters, in the order given.
    - `cost`: 1/2 |r|^2 at the start and at the optimum (`cost_start`, `cost`).
    - `sigma`: the noise level used for the covariance (given or estimated).
    - `iterations`: Levenberg-Marquardt steps taken; `solves`: forward solves
      (with their JVPs, one per parameter) the fit made, across all scenes.
    - `converged`, `message`: whether the solver met its tolerance, and why not.
    - `time`: wall time of the call, s (compilation included on a first call).
    - `processes`: worker processes of this host that evaluated the experiments
      (1: this process; 0: a user's executor).
    """

    scene: Scene
    scenes: tuple
    values: dict
    std: dict
    cov: np.ndarray
    names: tuple
    cost_start: float
    cost: float
    sigma: float
    iterations: int
    solves: int
    converged: bool
    message: str
    time: float
    processes: int = 1


def _stack_scenes(scenes):
    """The scenes as one pytree with a leading member axis on every array, when
    they share their structure (same static parts, array shapes and dtypes); else
    None."""
    parts = [eqx.partition(s, eqx.is_array) for s in scenes]
    arrays, static = parts[0]
    for a, st in parts[1:]:
        if jax.tree_util.tree_structure(a) != jax.tree_util.tree_structure(arrays):
            return None
        if not eqx.tree_equal(st, static):
            return None
        shapes = jax.tree_util.tree_map(lambda x, y: x.shape == y.shape, a, arrays)
        if not all(jax.tree_util.tree_leaves(shapes)):
            return None
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *[a for a, _ in parts])
    return eqx.combine(stacked, static)


class _Problem(eqx.Module):
    scenes: tuple
    # The scenes stacked along a member axis, solved in one vmap (None: one by one).
    stacked: Any
    getters: tuple = eqx.field(static=True)
    positive: tuple = eqx.field(static=True)
    residual_fn: Any
    config: SolveConfig
    ts: Any

    def values(self, theta):
        return [jnp.exp(t) if pos else t for t, pos in zip(theta, self.positive)]

    def with_values(self, scene, theta):
        vals = self.values(theta)
        current = [g(scene) for g in self.getters]
        vals = [v.astype(c.dtype) for v, c in zip(vals, current)]
        return eqx.tree_at(lambda s: [g(s) for g in self.getters], scene, vals)

    def residual(self, theta, scene, batched=False):
        # `adjoint="sensitivity"`: derivatives from sensitivities integrated with
        # the state; else forward mode through the solve. `batched`: under vmap
        # (stacked scenes).
        adjoint = self.config.adjoint_for("jacobian")
        if isinstance(adjoint, SensitivityAdjoint):
            return _sensitivity_residual(self, jnp.stack(theta), scene, batched)
        sc = self.with_values(scene, theta)
        traj = solve(sc, self.config, self.ts, adjoint=adjoint, batched=batched)
        return jnp.ravel(self.residual_fn(traj, sc))

    def flat_residual(self, traj, sc):
        return jnp.ravel(self.residual_fn(traj, sc))

    def residuals(self, theta, args=None):
        del args
        if self.stacked is not None:
            members = eqx.filter_vmap(
                lambda th, sc: self.residual(th, sc, batched=True), in_axes=(None, 0)
            )
            return jnp.ravel(members(theta, self.stacked))
        out = []
        for scene in self.scenes:
            out.append(self.residual(theta, scene))
        return jnp.concatenate(out)


@eqx.filter_custom_jvp
def _sensitivity_residual(problem, x, scene, batched):
    """The residuals at the parameters `x` (theta, stacked), with a JVP from the
    sensitivities integrated beside the state (along `x` only). `batched`: under
    vmap."""
    sc = problem.with_values(scene, list(x))
    return problem.flat_residual(solve(sc, problem.config, problem.ts), sc)


@_sensitivity_residual.def_jvp
def _sensitivity_residual_jvp(primals, tangents):
    problem, x, scene, batched = primals
    tx = tangents[1]
    r, d = derivatives(
        lambda xx: problem.with_values(scene, list(xx)),
        x,
        jnp.asarray(problem.positive),
        problem.config,
        problem.ts,
        problem.flat_residual,
        batched=batched,
    )
    return r, d.T @ (jnp.zeros_like(x) if tx is None else tx)


# --------------------------------------------------------------------------------------
# Experiments over worker processes


def _experiment(x, scene, problem):
    """One experiment's residuals and their Jacobian d r / d theta at `x` (theta
    stacked), in forward mode as Levenberg-Marquardt takes it in one process: the
    program a worker runs."""

    def f(xx):
        r = problem.residual([xx[i] for i in range(xx.shape[0])], scene)
        return r, r

    J, r = jax.jacfwd(f, has_aux=True)(x)
    return r, J


def _stack_outputs(outs):
    """The residuals and Jacobians of the experiments (`_experiment`), stacked."""
    rs = [np.asarray(out[0], np.float64) for out in outs]
    Js = [np.asarray(out[1], np.float64) for out in outs]
    return np.concatenate(rs), np.concatenate(Js)


def _evaluations(problem, x0, executor, workers):
    """The experiments of `problem` as programs evaluated in worker processes (or
    the processes of a jax.distributed job) at the parameters the host's
    Levenberg-Marquardt iteration asks for."""
    bare = _Problem((), None, *_problem_parts(problem))
    args = [(x0, scene, bare) for scene in problem.scenes]
    return _distribute.ExperimentPrograms(
        _experiment, args, executor, workers, _stack_outputs
    )


def _problem_parts(problem):
    return (
        problem.getters,
        problem.positive,
        problem.residual_fn,
        problem.config,
        problem.ts,
    )


def _evaluate(token, x, m):
    shapes = (
        jax.ShapeDtypeStruct((m,), jnp.float64),
        jax.ShapeDtypeStruct((m, x.shape[0]), jnp.float64),
    )
    return jax.pure_callback(
        _distribute.evaluate_registered, shapes, token, x, vmap_method="sequential"
    )


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _remote_residuals(token, x, m):
    return _evaluate(token, x, m)[0]


@_remote_residuals.defjvp
def _remote_residuals_jvp(m, primals, tangents):
    token, x = primals
    r, J = _evaluate(token, x, m)
    return r, J @ tangents[1]


class _Remote(eqx.Module):
    """The residuals of all experiments as the host's iteration sees them: one
    evaluation in the workers gives the residuals and their Jacobian (its JVPs)."""

    token: Any  # int array: the fit's `ExperimentPrograms` (`_distribute.register`)
    m: int = eqx.field(static=True)
    positive: tuple = eqx.field(static=True)

    def residuals(self, theta, args=None):
        del args
        return _remote_residuals(self.token, jnp.stack(theta), self.m)


def _workers(processes, executor, scenes, config) -> int:
    """Worker processes of this host for the experiments `scenes`: `processes`, or
    with "auto" one per experiment up to the host's cores where there are several
    experiments and `config` solves on a CPU (also on a GPU host, by default); 0
    for a user's executor."""
    return _distribute.experiment_workers(
        processes, executor, len(scenes), config.on_cpu()
    )


@cpu_jit
def _levenberg_marquardt(problem, theta0, rtol, atol, max_iters):
    sol = optx.least_squares(
        problem.residuals,
        optx.LevenbergMarquardt(rtol=rtol, atol=atol),
        theta0,
        max_steps=max_iters,
        throw=False,
    )
    theta = sol.value
    r0 = problem.residuals(theta0)

    def with_value(th):
        r = problem.residuals(th)
        return r, r

    # The residuals at the optimum and their Jacobian from one solve with one
    # tangent per parameter; in the parameters' own units: dr/dp = dr/dtheta / p
    # for log p.
    J, r = jax.jacfwd(with_value, has_aux=True)(theta)
    J = jnp.stack(J, axis=1)
    scale = jnp.stack(
        [jnp.where(pos, jnp.exp(t), 1.0) for t, pos in zip(theta, problem.positive)]
    )
    J = J / scale[None, :]
    return theta, r0, r, J, sol.result, sol.stats["num_steps"]


def _check_count(m, n):
    if m < n:
        raise ValueError(
            f"`residual_fn` must return at least {n} residuals (one per "
            f"parameter); got {m}."
        )


def _check_bounds(bounds, labels, starts):
    if bounds is None:
        return None
    if not isinstance(bounds, dict):
        raise ValueError("`bounds` must be a dict label -> (low, high).")
    for name, b in bounds.items():
        if name not in labels:
            raise ValueError(
                f"`bounds` names {name!r}, which is not among `params` {labels}."
            )
        try:
            low, high = (float(x) for x in b)
        except (TypeError, ValueError):
            raise ValueError(
                f"`bounds[{name!r}]` must be a pair (low, high) of numbers; got "
                f"{show(b)}."
            ) from None
        if math.isnan(low) or math.isnan(high) or not low < high:
            raise ValueError(
                f"`bounds[{name!r}]` must be (low, high) with low < high (no NaN; "
                f"inf for no bound); got ({low!r}, {high!r})."
            )
        p0 = starts[labels.index(name)]
        if not (low <= p0 <= high):
            raise ValueError(
                f"`bounds` for {name!r} = ({low}, {high}) exclude the start value "
                f"{p0:.6g}; valid: bounds that contain the scene's value."
            )
    return bounds


@single_blas_thread
def least_squares(
    scene: Scene | Sequence[Scene],
    residual_fn: Callable,
    params: Sequence,
    *,
    bounds: dict | None = None,
    positive: bool | Sequence[bool] = True,
    sigma: float | None = None,
    max_iters: int = 50,
    tol: float = 1e-8,
    verbose: bool = False,
    processes="auto",
    executor=None,
    config: SolveConfig | None = None,
    **options,
) -> LeastSquaresResult:
    """Fit parameter leaves of a scene to measurements by nonlinear least squares.

    **Arguments:**

    - `scene`: the starting scene, or a list of scenes (several experiments sharing
      the parameters: each must hold every named parameter; their residuals are
      stacked; scenes of one structure, such as two release angles, are solved
      together in one vmap, others one after another). Its values of `params`
      are the initial guess.
    - `residual_fn`: `residual_fn(traj, scene) -> array` of residuals in units of the
      measurement (model minus data), for `traj` the scene's Trajectory at `ts`. Data
      it closes over are compiled in as constants; an `eqx.Module` with array fields
      is traced (new data reuse the compiled fit).
    - `params`: the leaves to fit, by name, path or callable, as in `fit`.
    - `bounds`: dict label -> (low, high); the start must lie inside. The fitted
      values are checked against them (`converged` is False outside).
    - `positive`: fit log p (one bool, or one per parameter).
    - `sigma`: the measurement noise for the covariance (default: estimated).
    - `max_iters`, `tol`: Levenberg-Marquardt's iteration limit and its relative
      and absolute tolerance on the parameters (in log p where positive).
    - `verbose`: print the result.
    - `processes`: `"auto"` (default: with two or more experiments solved on a CPU,
      as they are under `device="auto"` also on a GPU host, one worker process per
      experiment up to the host's cores; else this process alone), or the number
      of worker processes. With workers, each
      Levenberg-Marquardt iteration sends the current parameters to them; each
      experiment's residuals and their Jacobian come from one program per
      experiment structure, traced once in this process and run in jaxstring's
      own pool of spawned processes (the pool `sweep` uses, kept for later
      calls; compilation shared through the persistent compilation cache), and
      the step is taken here. Each experiment is then solved on its own, as one
      process solves experiments of different structures; experiments of one
      structure, which one process solves in one vmap, agree with it to about
      the solver's tolerance rather than to rounding. Measured:
      docs/performance.md, "Identification over processes".
      In a `jax.distributed` job the experiments are split over the job's
      processes (experiment i in process i mod N, in its workers if it has
      any), and every process gathers all of them and takes the same steps.
    - `executor`: any `concurrent.futures.Executor` whose workers can import
      jaxstring (a `ProcessPoolExecutor`, a Dask cluster's executor) to evaluate
      the experiments instead. A worker that dies is replaced and its experiment
      evaluated again; an experiment whose evaluation fails twice ends the fit
      with `converged=False` and a message naming the experiment.
    - `config`: the `SolveConfig` of the forward solves (default:
      `SolveConfig.default("identify")`); `options`: its fields as shortcuts
      (`ts`, the save times the residuals use; `solver`, `rtol`, `atol`,
      `max_steps`, ...). Its `adjoint` says how the Jacobian of the residuals is
      computed: `"auto"`/`"forward"` (forward mode through the solve) or
      `"sensitivity"` (the sensitivities integrated beside the state under the
      solver's error control: accurate where the state's own steps do not resolve
      the derivative, as through slack-and-snap motions; not for projecting
      models).

    **Returns:** a `LeastSquaresResult`. A fit that does not converge says so and
    why (`converged`, `message`); it does not raise.
    """
    scenes = tuple(scene) if isinstance(scene, (list, tuple)) else (scene,)
    if not scenes or not all(isinstance(s, Scene) for s in scenes):
        raise ValueError(
            "`scene` must be a jaxstring Scene or a non-empty list of Scenes."
        )
    if not callable(residual_fn):
        raise ValueError("`residual_fn` must be callable: residual_fn(traj, scene).")
    getters, positive = resolve_params(scenes[0], params, positive)
    getters, positive = tuple(getters), tuple(positive)
    for sc in scenes[1:]:
        for p in [params] if isinstance(params, str) or callable(params) else params:
            resolve(sc, p)  # every experiment holds every parameter
    labels = [g.label for g in getters]
    starts = []
    for g, pos, label in zip(getters, positive, labels):
        leaf = g(scenes[0])
        if jnp.shape(leaf) != ():
            raise ValueError(f"`params`: {label!r} must be a scalar leaf.")
        v = float(leaf)
        if not math.isfinite(v) or (pos and v <= 0):
            raise ValueError(
                f"`params`: {label!r} starts at {v!r}; a positive parameter needs a "
                "finite start > 0 (or pass positive=False)."
            )
        starts.append(v)
    bounds = _check_bounds(bounds, labels, starts)
    check_positive("tol", tol)
    check_int("max_iters", max_iters, 1)
    _distribute.check_workers(processes, executor)
    if sigma is not None:
        check_positive("sigma", sigma)
    config = identify_config(scenes[0], config, options, "jacobian")
    for sc in scenes[1:]:
        config.check_scene(sc)
    check_jacobian_adjoint(config)
    ts = config.save_times(scenes[0].t0, scenes[0].t1)
    config = config.replace(ts=None)
    workers = _workers(processes, executor, scenes, config)
    theta0 = [
        jnp.asarray(math.log(v) if pos else v, jnp.float64)
        for v, pos in zip(starts, positive)
    ]
    start = time.perf_counter()
    one = len(scenes) == 1 or not _distribute.distributed()
    if executor is None and workers == 1 and one:
        stacked = _stack_scenes(scenes) if len(scenes) > 1 else None
        problem = _Problem(scenes, stacked, getters, positive, residual_fn, config, ts)
        problem, theta0 = config.placed((problem, theta0))
        # The residuals' structure, before anything compiles.
        m = eqx.filter_eval_shape(problem.residuals, theta0).shape[0]
        _check_count(m, len(getters))
        theta, r0, r, J, result, iters = jax.block_until_ready(
            _levenberg_marquardt(problem, tuple(theta0), tol, tol, max_iters)
        )
        failed = {}
    else:
        # Each experiment's residuals and Jacobian in a worker process, the
        # Levenberg-Marquardt iteration in this one.
        problem = _Problem(scenes, None, getters, positive, residual_fn, config, ts)
        evaluations = _evaluations(problem, jnp.stack(theta0), executor, workers)
        m = sum(out[0].shape[0] for out in evaluations.outputs)
        _check_count(m, len(getters))
        remote = _Remote(jnp.asarray(_distribute.register(evaluations)), m, positive)
        try:
            theta, r0, r, J, result, iters = jax.block_until_ready(
                _levenberg_marquardt(remote, tuple(theta0), tol, tol, max_iters)
            )
        finally:
            _distribute.release(evaluations)
        failed = evaluations.failed
    elapsed = time.perf_counter() - start
    r0, r, J = np.asarray(r0), np.asarray(r), np.asarray(J)
    if not failed and not np.all(np.isfinite(r0)):
        raise ValueError(
            "`residual_fn` returned NaN or inf at the start values: check the data "
            "and that the start scene solves."
        )
    m, n = r.size, len(getters)
    s = float(sigma) if sigma is not None else math.sqrt(float(r @ r) / max(m - n, 1))
    JTJ = J.T @ J
    cov = (
        s**2 * np.linalg.pinv(JTJ)
        if np.all(np.isfinite(JTJ))
        else np.full((n, n), np.nan)
    )
    values = [float(v) for v in problem.values(theta)]
    converged = bool(result == optx.RESULTS.successful)
    if converged:
        message = "converged"
    elif int(iters) >= max_iters:
        message = f"not converged: max_iters = {max_iters} iterations reached"
    else:
        message = (
            "not converged: the Levenberg-Marquardt iteration failed (a solve failed "
            "or the residuals are not finite)"
        )
    if failed:
        i, reason = min(failed.items())
        converged = False
        message = f"not converged: the evaluation of experiment {i} failed ({reason})"
    if converged and bounds is not None:
        for name, (low, high) in bounds.items():
            v = values[labels.index(name)]
            if not (low <= v <= high):
                converged = False
                message = f"the optimum {name} = {v:.6g} lies outside its bounds"
    if converged and not np.all(np.isfinite(r)):
        converged, message = False, "the residuals at the optimum are not finite"
    fitted = tuple(problem.with_values(sc, theta) for sc in scenes)
    iters = int(iters)
    res = LeastSquaresResult(
        scene=fitted[0],
        scenes=fitted,
        values=dict(zip(labels, values)),
        std=dict(zip(labels, np.sqrt(np.abs(np.diag(cov))).tolist())),
        cov=cov,
        names=tuple(labels),
        cost_start=0.5 * float(r0 @ r0),
        cost=0.5 * float(r @ r),
        sigma=s,
        iterations=iters,
        # each LM step: one solve per scene with its JVPs; plus the start and
        # the optimum with its Jacobian
        solves=(iters + 2) * len(scenes),
        converged=converged,
        message=message,
        time=elapsed,
        processes=workers,
    )
    if verbose:
        vals = "  ".join(
            f"{k}={v:.6g} (+- {res.std[k]:.2g})" for k, v in res.values.items()
        )
        print(f"least_squares: {message}; {iters} iterations, {elapsed:.2f} s; {vals}")
    return res
