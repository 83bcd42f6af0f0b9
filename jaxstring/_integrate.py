"""The one integration behind every solve: `integrate` is jaxstring's only call of
`diffrax.diffeqsolve`, and of its own step loop for the solves that reverse mode
does not differentiate (`jaxstring._solvers.loop`).

`solve(scene, config)` integrates a scene. Other solves hand `integrate` a
transformed vector field and state: the forward sensitivities of `fit` and
`least_squares` (`jaxstring._sensitivity`: the state with its derivatives beside it)
and the members of a lockstep sweep (`jaxstring._sweep`: the members' states
stacked), with the solver and controller that `solver_parts` builds for the scene.
"""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu

from . import _programs
from ._arrays import host_map, host_op, on_host
from ._jit import cpu_jit
from ._lazy import diffrax as dfx
from ._scene import Scene, scene_vector_field
from ._solve_config import SolveConfig
from ._trajectory import Trajectory
from ._validate import check_times


def solver_parts(scene: Scene, config: SolveConfig, norm=None, differentiable=True):
    """The diffrax solver (before any projection wrapper), step-size controller and
    initial step of `scene` under `config`, as every solve builds them. `norm`: the
    controller's error norm (default: RMS). `differentiable`: False for a solve
    that nothing differentiates (`solve`)."""
    # the solvers import diffrax: not imported by a process that only runs saved
    # programs (`jaxstring._lazy`)
    from ._solvers.registry import build_solver
    from ._solvers.step_size import make_controller

    nr, na = config.newton_tolerances()
    solver = build_solver(config.solver, nr, na, scene, differentiable)
    kw = {} if norm is None else {"norm": norm}
    controller = make_controller(
        config.solver,
        config.rtol,
        config.atol,
        config.adaptive,
        config.step_control,
        **kw,
    )
    return solver, controller, config.initial_step()


def integrate(
    vector_field,
    y0,
    args,
    t0,
    t1,
    *,
    solver,
    controller,
    dt0,
    saveat,
    max_steps,
    adjoint=None,
    progress=False,
    batched=False,
):
    """Integrate dy/dt = `vector_field(t, y, args)` from `y0` over [t0, t1]: the
    one `diffeqsolve` of the package. Never throws: the solution's `result` says
    whether it succeeded, with the data up to a failure. The save times of
    `saveat` must lie in [t0, t1] and increase (the callers check them before
    anything is traced). A solve that reverse mode does not differentiate runs
    jaxstring's own step loop (`jaxstring._solvers.loop`: the same values from a
    smaller program); `batched`: traced under `vmap` (its loops are then
    equinox's, which write a saved row at a time)."""
    from ._solvers import loop
    from ._solvers.diffrax_compat import save_times_checked

    if loop.serves(solver, controller, adjoint, progress, saveat):
        sub = saveat.subs
        return loop.solve(
            vector_field, y0, args, t0, t1, solver=solver, controller=controller,
            dt0=dt0, ts=sub.ts, fn=sub.fn, max_steps=max_steps, batched=batched,
        )  # fmt: skip
    meter = (
        dfx.TextProgressMeter(minimum_increase=0.05)
        if progress
        else dfx.NoProgressMeter()
    )
    kw = {} if adjoint is None else {"adjoint": adjoint}
    with save_times_checked():
        return dfx.diffeqsolve(
            dfx.ODETerm(vector_field),
            solver,
            t0=t0,
            t1=t1,
            dt0=dt0,
            y0=y0,
            args=args,
            saveat=saveat,
            stepsize_controller=controller,
            max_steps=max_steps,
            throw=False,
            progress_meter=meter,
            **kw,
        )


def _projected(solver, adjoint):
    """`solver` wrapped to project onto the model's constraint after every step."""
    from ._solvers.projected import ProjectedSolver, ProjectedSolverAD

    if type(adjoint) is dfx.RecursiveCheckpointAdjoint and adjoint.checkpoints is None:
        return ProjectedSolver(solver)
    # diffrax sets the stage loop of a Runge-Kutta solver to a kind it can
    # differentiate in forward mode / with DirectAdjoint, but cannot see through
    # the wrapper: do it before wrapping.
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
    return ProjectedSolverAD(solver)


def solve_scene(
    scene: Scene,
    config: SolveConfig,
    saveat,
    adjoint=None,
    differentiable=True,
    batched=False,
):
    """`integrate`'s solution of `scene` under `config`, saved as `saveat(fn)`
    says, `fn` the projection onto the constraint manifold for a projected solve
    (None: the state as is). E.g. every step:
    `saveat=lambda fn: dfx.SaveAt(steps=True)`.
    `adjoint`: a diffrax adjoint (default: the configuration's for a gradient).
    `differentiable`: False for a solve that nothing differentiates (`solve`).
    `batched`: traced under `vmap` (`integrate`)."""
    if not differentiable:
        adjoint = dfx.ForwardMode()  # plain while loops: nothing to checkpoint
    elif adjoint is None:
        adjoint = config.adjoint_for("gradient")
    solver, controller, dt0 = solver_parts(scene, config, differentiable=differentiable)
    save_fn = None
    if config.project and scene.model.projects:
        solver = _projected(solver, adjoint)
        save_fn = lambda t, y, args: args.model.project(y)
    return integrate(
        scene_vector_field,
        scene.y0,
        scene,
        scene.t0,
        scene.t1,
        solver=solver,
        controller=controller,
        dt0=dt0,
        saveat=saveat(save_fn),
        max_steps=config.max_steps,
        adjoint=adjoint,
        progress=config.progress,
        batched=batched,
    )


def solve(
    scene: Scene,
    config: SolveConfig,
    ts=None,
    adjoint=None,
    differentiable=True,
    batched=False,
) -> Trajectory:
    """Integrate `scene` under `config` and return its Trajectory.

    Usable inside `jax.grad`, `jax.vmap` and `jit`: no check here looks at array
    values (the scene may be traced); `config` was checked when it was built. `ts`
    (default: the configuration's save times) and `adjoint` (a diffrax adjoint;
    default: the configuration's for a gradient) override the configuration. A
    failed solve does not raise: the Trajectory's `result` says why, with the data
    up to the failure.

    `differentiable=False` is for a solve whose result nothing differentiates (a
    saved program, a call on concrete arrays, a sweep's members): the same values,
    from a smaller trace. The steps then run in jaxstring's own loop of plain
    while loops (`jaxstring._solvers.loop`) rather than diffrax's checkpointed
    ones of reverse mode, and jaxstring's Kvaerno and BDF do not wrap their
    Newton solves in `custom_root`, whose derivative rule JAX traces with every
    solve (performance.md, "Compile time"). `batched`: the solve is traced under
    `vmap` (a sweep's members).
    """
    if ts is None:
        ts = config.save_times(scene.t0, scene.t1)
    check_times("ts", ts, scene.t0, scene.t1)  # (values known here only)
    ts = jnp.asarray(ts, dtype=jnp.float64)
    sol = solve_scene(
        scene,
        config,
        lambda fn: dfx.SaveAt(ts=ts) if fn is None else dfx.SaveAt(ts=ts, fn=fn),
        adjoint,
        differentiable,
        batched,
    )
    return Trajectory.from_solution(ts, sol.ys, sol.result, sol.stats, scene)


jit_solve = cpu_jit(solve)


def _solve_values(scene, config, ts):
    """`solve` for concrete arguments, whose result nothing differentiates."""
    return solve(scene, config, ts, differentiable=False)


jit_solve_values = cpu_jit(_solve_values)


def _solve_fields(scene, config, ts):
    """`solve`'s Trajectory as a dict of arrays (a saved program's output: never
    differentiated)."""
    traj = solve(scene, config, ts, differentiable=False)
    return {f.name: getattr(traj, f.name) for f in dataclasses.fields(traj)}


def padded_length(n: int) -> int:
    """The number of save times a compiled solve is traced for when `n` are asked:
    the next power of two (at least 8) up to 4096, the next multiple of 4096 above.
    Solves of one scene structure with 11, 41 or 101 save times share one program,
    so a new `n_save` or `ts` rarely costs a compilation."""
    if n <= 4096:
        return max(8, 1 << (n - 1).bit_length())
    return -(-n // 4096) * 4096


def _padded(ts):
    """`ts` with its last time repeated up to `padded_length(len(ts))` entries
    (diffrax saves a repeated time twice)."""
    n = ts.shape[0]
    extra = padded_length(n) - n
    if extra == 0:
        return ts
    return host_op(
        lambda xp, ts: xp.concatenate([ts, xp.broadcast_to(ts[-1:], (extra,))]), ts
    )


def _cut_rows(rows, n):
    """`rows` (save-time arrays, a valid count) cut to their first `n` rows."""
    arrays, n_valid = rows
    return jtu.tree_map(lambda x: x[:n], arrays), jnp.minimum(n_valid, n)


# The cut as one compiled program, for concrete arrays (a nested jit takes no
# compiler options). XLA's optimisations have nothing to do in a program of
# slices; without them it compiles in about half the time.
_cut = jax.jit(
    _cut_rows, static_argnums=1, compiler_options={"xla_backend_optimization_level": 0}
)


CUT_COMPILED_AFTER = 16
"""A cut of the same arrays and save count done this many times on the host in a
process (a loop of solves) runs compiled from then on."""

_HOST_CUTS: dict = {}  # the cuts done on the host in this process -> how many times


def _first_rows(traj: Trajectory, n: int) -> Trajectory:
    """`traj` cut to its first `n` save times (the padded ones dropped): `t_end` is
    the same, as the padding repeats the last time.

    On the host (`host_map`: no compilation, but a transfer call per array back
    to the device), until the same cut has come `CUT_COMPILED_AFTER` times: then
    as one compiled program (`_cut`), whose compilation a loop of many solves
    pays back (docs/performance.md, "Compile time"). Traced arrays (a caller's
    jit, vmap or grad) are sliced in the caller's trace, arrays on another
    device by the compiled program."""
    if traj.ts.shape[0] == n:
        return traj
    rows = ((traj.ts, traj.ys, traj.obs), traj.n_valid)
    leaves, treedef = jtu.tree_flatten(rows)
    if any(isinstance(x, jax.core.Tracer) for x in leaves):
        (ts, ys, obs), n_valid = _cut_rows(rows, n)
        return dataclasses.replace(traj, ts=ts, ys=ys, obs=obs, n_valid=n_valid)
    key = (n, treedef, tuple((x.shape, x.dtype) for x in leaves))
    done = _HOST_CUTS.get(key, 0)
    if done >= CUT_COMPILED_AFTER or not all(on_host(x) for x in leaves):
        (ts, ys, obs), n_valid = _cut(rows, n)
    else:
        _HOST_CUTS[key] = done + 1
        ts, ys, obs = host_map(lambda xp, x: x[:n], rows[0])
        n_valid = host_op(lambda xp, v: xp.minimum(v, n), traj.n_valid)
    return dataclasses.replace(traj, ts=ts, ys=ys, obs=obs, n_valid=n_valid)


def solve_compiled(scene: Scene, config: SolveConfig, ts) -> Trajectory:
    """`solve`, compiled, for save times padded to `padded_length` and cut back;
    through a saved program where one can be saved (see `jaxstring._programs`)."""
    n = ts.shape[0]
    ts = _padded(ts)
    # the padded times decide the save times; n_save is static, so one value serves
    config = config.replace_unchecked(n_save=ts.shape[0])
    if not config.progress and _programs.usable((scene, config, ts)):
        fields = _programs.call(_solve_fields, scene, config, ts)
        if fields is not None:
            return _first_rows(Trajectory(**fields), n)
    leaves = jtu.tree_leaves((scene, config, ts))
    traced = any(isinstance(x, jax.core.Tracer) for x in leaves)
    jitted = jit_solve if traced else jit_solve_values
    return _first_rows(jitted(scene, config, ts), n)
