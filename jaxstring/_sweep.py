"""sweep: evaluate a scene over a batch or grid of parameter values in one call.

Each member is the scene with some array leaves replaced (by name or path, as in
`fit`); all members are integrated by one `jax.vmap` of the same solve inside one
`eqx.filter_jit`. Failures do not abort the sweep: the solve never throws, and each
member carries its own diffrax result code (`ok`, `status`).

Why plain vmap is not enough on a CPU: a vmapped adaptive solve runs its members in
lockstep -- every loop iteration advances all members, each with its own step size,
until the slowest is done -- so the cost is (largest number of steps) x (members),
against the sum of the steps for a loop. What helps (measurements, and the designs
not adopted: docs/numerics.md, "Sweeps: vmap, groups and lockstep"):

* sharding: with several devices the members are split into one shard per
  device, each committed to its device, so that each device runs its own solver
  loop, with no synchronisation between devices. The shards are dispatched
  asynchronously from the calling thread: GPUs run them at the same time, while
  XLA:CPU runs a call's solver loops in the dispatching thread, so the CPU devices
  of ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` run theirs one after the
  other.
* compiler options: the sweeps compile without XLA:CPU's YNNPACK fusions
  (`jaxstring._jit.cpu_jit`), which run the small reductions of vmapped string
  models several times slower.
* grouping (`batch_size`): members run in groups of `batch_size` (vmap inside a
  `lax.map`), so a slow member only holds up its own group; with `order="sort"` members
  are grouped by their parameter values, so that similar members (similar stiffness,
  similar step sequences) share a group.
* vmap with BDF: the displacement string's BDF step has no branch (a fresh
  Jacobian every step), so vmap computes nothing twice, and a step at k = 20-40 is
  a few hundred kernel launches that cost about the same for 16 members as for
  one (against a loop of CVODE runs: docs/performance.md, "A sweep against a peer
  loop").
* lockstep (`mode="lockstep"`), the fast one for the Kvaerno and fixed-step
  solvers: what costs in a vmapped solve is less
  the lockstep itself than what vmap makes of the solver's control flow: every
  `lax.cond` (Jacobian refresh, first-stage Jacobian, step rejection) becomes
  "compute both branches", and every while loop runs masked iterations (a shared
  step sequence has about as many steps as the slowest member alone, so the gain
  of lockstep mode over vmap is per iteration). Lockstep
  mode makes the members *one* ODE on the stacked state `(M, ...)` (vector field: a
  vmap of the member vector field over the members' scenes), so the solver's
  control flow stays scalar: one step sequence, accepted when every member's own
  RMS error norm is within the tolerance (`member_rms_max`), and a stage Newton
  iteration whose Newton matrix is block-diagonal: per-member Jacobians from the
  JVPs of one member (all members seeded at once) and per-member factorisations
  (`StageNewton(linear_solver="batched")`), never an `(M n) x (M n)` matrix. Each
  member is then integrated at least as finely as alone (its results differ from
  a `simulate` call by about the tolerance, not by rounding). A failure of any
  member stops the shared solve; `fallback=True` then re-runs the members one solve
  each (vmap mode), so that each gets its own status.
* lockstep with a fixed step (`solver` "implicit_euler_fixed", "theta",
  "trapezoid"): every member takes the same steps as its own `simulate` call, so
  the group differs from the loop only by how far each step's (full, quadratically
  convergent) Newton iteration is converged: with `newton_rtol = newton_atol =
  1e-10`, to rounding. The members' node-major states are concatenated along the
  node axis (`_FlatBatch`): member blocks never couple, so the Jacobian of the
  group is block-tridiagonal like one long string's, and the fixed-step solver's
  own banded path (colouring JVPs, block cyclic reduction) serves the whole group.

Where the time goes: a step of a single solve is mostly the per-iteration overhead
of the solver loops, not the implicit step's arithmetic (vector field, coloured
JVPs, banded Jacobian, factorisation, solves), and a group shares that overhead
between its members (profile: docs/numerics.md, "Sweeps: vmap, groups and
lockstep").
"""

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from . import _distribute, _programs
from ._arrays import as_array
from ._blas import single_blas_thread
from ._integrate import integrate, solve
from ._jit import cpu_jit
from ._lazy import diffrax as dfx
from ._parameters import _follow, parameter_names, resolve
from ._presets import solver_for
from ._scene import Scene
from ._solve_config import SolveConfig, solve_config
from ._trajectory import Trajectory
from ._validate import check_choice, check_int, show


class SweepResult(eqx.Module):
    """What `sweep` returns (NumPy arrays; leading axes = the sweep's shape).

    **Fields:**

    - `values`: dict name -> parameter values of the members, shape `shape`.
    - `out`: `fn(traj, scene)` of every member (any pytree of arrays), each leaf with
      leading axes `shape`. Members that failed hold the values `fn` gives on their
      partial trajectory (NaN after the failure).
    - `ok`: bool array `shape`: the member's solve succeeded.
    - `result`: diffrax result codes, int array `shape` (0 = success).
    - `status`: list (flattened members) of 'success' or the solver's message.
    - `stats`: dict of solver statistics per member (`num_steps`, ...).
    - `shape`: the sweep's shape (grid axes, or `(n,)` for a batch).
    - `n_devices`: devices the members were spread over.
    - `mode`: how the members were integrated: `"vmap"`, `"lockstep"`, or
      `"lockstep, then vmap"` (the shared solve failed and the members were
      re-run one solve each, to isolate the failure).
    - `time`: seconds for the call (compilation included on a first call; a second
      call with the same structure reuses the compiled sweep).
    - `processes`: worker processes of this host that ran the members (1: this
      process; 0: a user's executor).
    """

    values: dict
    out: Any
    ok: np.ndarray
    result: np.ndarray
    status: list
    stats: dict
    shape: tuple
    n_devices: int
    time: float
    mode: str = "vmap"
    processes: int = 1


def _default_fn(traj, scene):
    del scene
    return traj.obs


def _member(vals, scene, getters, fn, config, ts):
    sc = eqx.tree_at(
        lambda s: [g(s) for g in getters],
        scene,
        [v.astype(g(scene).dtype) for v, g in zip(vals, getters)],
    )
    # a sweep's: values only, vmapped (`_run_group`)
    traj = solve(sc, config, ts, differentiable=False, batched=True)
    stats = {k: v for k, v in traj.stats.items() if k != "max_steps"}
    return fn(traj, sc), traj.result, stats


def _run_group(vals, scene, getters, fn, config, ts, batch_size):
    """The members in groups of `batch_size` (a vmap each, one after the other);
    the callers make the number of members a multiple of it, so that every member
    is integrated by the same group program wherever it runs."""
    member = lambda v: _member(v, scene, getters, fn, config, ts)
    if batch_size >= vals[0].shape[0]:
        return jax.vmap(member)(vals)
    return jax.lax.map(member, vals, batch_size=batch_size)


# The sweeps compile without XLA:CPU's YNNPACK fusions (`jaxstring._jit`; measured:
# docs/numerics.md, "Sweeps: vmap, groups and lockstep").
@cpu_jit
def _sweep_local(vals, scene, getters, fn, config, ts, batch_size):
    return _run_group(vals, scene, getters, fn, config, ts, batch_size)


# --------------------------------------------------------------------------------------
# Lockstep: all members as one ODE with one shared step sequence


# The adaptive solvers of the lockstep mode -> their diffrax class (the Kvaerno
# methods' class is the scene's: `kvaerno_class`).
LOCKSTEP_SOLVERS = {
    "kvaerno3": None,
    "kvaerno4": None,
    "kvaerno5": None,
    "implicit_euler": "ImplicitEuler",
    "tsit5": "Tsit5",
    "dopri5": "Dopri5",
}


def member_rms_max(tree):
    """Largest per-member RMS norm of a stacked pytree (leading axis = members).

    The norm of the shared step-size controller and stage Newton iteration of the
    lockstep mode: a step is accepted (a Newton iteration has converged) only when
    it is for *every* member by that member's own RMS norm, so each member is
    integrated at least as accurately as by its own solve at the same tolerances.
    """
    leaves = jtu.tree_leaves(tree)
    sq = sum(jnp.sum(jnp.abs(x.reshape(x.shape[0], -1)) ** 2, axis=1) for x in leaves)
    size = sum(math.prod(x.shape[1:]) for x in leaves)
    return jnp.max(jnp.sqrt(sq / size))


def _with_values(scene, getters, vals):
    return eqx.tree_at(
        lambda s: [g(s) for g in getters],
        scene,
        [jnp.asarray(v).astype(g(scene).dtype) for v, g in zip(vals, getters)],
    )


class _Batch(eqx.Module):
    """The members of a lockstep sweep: the base scene and the swept values
    `(M,)` per parameter. Its vector field maps the stacked states `(M, ...)` by a
    vmap of the member vector field over the members' scenes."""

    vals: tuple
    scene: Scene
    getters: tuple

    def member(self, v) -> Scene:
        return _with_values(self.scene, self.getters, v)

    def vector_field(self, t, ys):
        return jax.vmap(lambda v, y: self.member(v).vector_field(t, y))(self.vals, ys)

    # `ProjectedSolver` projects with `args.model.project`: the batch is its own
    # "model", projecting each member with its own scene's model.
    @property
    def model(self):
        return self

    def project(self, ys):
        return jax.vmap(lambda v, y: self.member(v).model.project(y))(self.vals, ys)


def _batch_vector_field(t, y, batch):
    return batch.vector_field(t, y)


class _FlatBatch(eqx.Module):
    """The members of a fixed-step lockstep sweep with their node-major states
    `(n_nodes, b)` concatenated along the node axis: one state `(M n_nodes, b)`.
    Member blocks never couple, so the Jacobian of the stacked vector field is
    block-tridiagonal like a single string's (zero blocks between members) and the
    fixed-step solvers' own banded path (colouring JVPs, block cyclic reduction
    over all M n_nodes nodes) handles the batch with no batched code."""

    batch: _Batch
    shape: tuple = eqx.field(static=True)  # (M, n_nodes, b)

    def vector_field(self, t, y):
        return self.batch.vector_field(t, y.reshape(self.shape)).reshape(y.shape)

    @property
    def model(self):
        return self

    def project(self, y):
        return self.batch.project(y.reshape(self.shape)).reshape(y.shape)


# Fixed-step solvers (damped full Newton, `_solvers.fixed_step`) by name -> theta.
LOCKSTEP_FIXED = {"implicit_euler_fixed": 1.0, "theta": 0.5, "trapezoid": 0.5}


def _lockstep_solver(config, scene):
    from ._solvers.fixed_step import ThetaMethod
    from ._solvers.registry import _MAX_ITERS_ADAPTIVE, kvaerno_class
    from ._solvers.stage_newton import StageNewton

    name = config.solver
    nr, na = config.newton_tolerances()
    if name in LOCKSTEP_FIXED:
        return ThetaMethod(theta=LOCKSTEP_FIXED[name], rtol=nr, atol=na)
    if LOCKSTEP_SOLVERS[name] is None:
        cls = kvaerno_class(name, scene)
    else:
        cls = getattr(dfx, LOCKSTEP_SOLVERS[name])
    if name in ("tsit5", "dopri5"):
        return cls()
    chord = StageNewton(
        rtol=nr,
        atol=na,
        norm=member_rms_max,
        max_iters=_MAX_ITERS_ADAPTIVE,
        linear_solver="batched",
    )
    return cls(root_finder=chord, root_find_max_steps=_MAX_ITERS_ADAPTIVE)


@cpu_jit
def _sweep_lockstep(vals, scene, getters, fn, config, ts, batch_size):
    """Lockstep solves of the members, all at once or in consecutive groups of
    `batch_size` (each group its own shared step sequence; `lax.map`)."""
    n = vals[0].shape[0]
    if batch_size is None or batch_size >= n:
        return _lockstep(vals, scene, getters, fn, config, ts)
    n_groups = -(-n // batch_size)
    pad = n_groups * batch_size - n
    # Pad with copies of the last member (dropped again below).
    grouped = tuple(
        jnp.concatenate([v, jnp.repeat(v[-1:], pad)]).reshape(n_groups, batch_size)
        for v in vals
    )
    out = jax.lax.map(lambda g: _lockstep(g, scene, getters, fn, config, ts), grouped)
    return jtu.tree_map(lambda x: x.reshape((-1,) + x.shape[2:])[:n], out)


def _lockstep(vals, scene, getters, fn, config, ts):
    """Integrate all members as one ODE on the stacked state `(M, ...)`.

    One adaptive step sequence for all (controller norm: `member_rms_max`); the
    stage Newton matrix is block-diagonal over the members and is built and
    factorised per member (`StageNewton(linear_solver="batched")`), never as an
    `(M n) x (M n)` matrix. Unlike a vmapped solve, the solver's loop and its
    branches (Jacobian refresh, step rejection) stay scalar: no member waits in a
    masked loop iteration, and no `lax.cond` turns into "compute both branches".
    """
    from ._solvers.diffrax_compat import result_code
    from ._solvers.projected import ProjectedSolver
    from ._solvers.step_size import make_controller

    batch = _Batch(vals, scene, getters)
    n = vals[0].shape[0]
    y0 = jnp.broadcast_to(scene.y0, (n,) + jnp.shape(scene.y0))
    solver = _lockstep_solver(config, scene)
    args = batch
    flat = config.solver in LOCKSTEP_FIXED
    if flat:
        # Node-major member states concatenated along the node axis (see
        # `_FlatBatch`).
        args = _FlatBatch(batch, tuple(y0.shape))
        y0 = y0.reshape((-1,) + y0.shape[2:])
    if config.project and scene.model.projects:
        solver = ProjectedSolver(solver)
        saveat = dfx.SaveAt(ts=ts, fn=lambda t, y, args: args.project(y))
    else:
        saveat = dfx.SaveAt(ts=ts)
    sol = integrate(
        _batch_vector_field,
        y0,
        args,
        scene.t0,
        scene.t1,
        solver=solver,
        # the controller `simulate` uses for this solver (NewtonLimitedController
        # for the Kvaerno family), on the member-wise max norm
        controller=make_controller(
            config.solver,
            config.rtol,
            config.atol,
            config.adaptive,
            config.step_control,
            norm=member_rms_max,
        ),
        dt0=config.initial_step(),
        saveat=saveat,
        max_steps=config.max_steps,
        # values only: jaxstring's own step loop (`jaxstring._solvers.loop`)
        adjoint=dfx.ForwardMode(),
    )
    stats = {
        key: jnp.broadcast_to(sol.stats[key], (n,))
        for key in ("num_steps", "num_accepted_steps", "num_rejected_steps")
    }

    def post(v, ys):
        sc = batch.member(v)
        traj = Trajectory.from_solution(ts, ys, sol.result, sol.stats, sc)
        return fn(traj, sc)

    ys_all = sol.ys
    if flat:
        ys_all = ys_all.reshape((ys_all.shape[0], n) + jnp.shape(scene.y0))
    out = jax.vmap(post)(vals, jnp.swapaxes(ys_all, 0, 1))
    codes = jnp.broadcast_to(result_code(sol.result), (n,))
    return out, codes, stats


def _sweep_devices(local, vals, scene, getters, fn, config, ts, batch_size, devices):
    """Split the members over `devices`, one shard each, and run the shards.

    Each shard is committed to its device (`jax.device_put`) and dispatched from
    the calling thread; JAX dispatches asynchronously, so devices that run their
    programs asynchronously (GPUs) integrate their shards at the same time. XLA:CPU
    runs a call's solver loops in the dispatching thread, so CPU devices run their
    shards one after the other. (One dispatching thread per CPU device would run
    them side by side, but deadlocks inside XLA:CPU on vmapped BDF groups:
    docs/performance.md, "A sweep against a peer loop".)
    """
    n_dev = len(devices)
    size = vals[0].shape[0] // n_dev
    outs = []
    for i, dev in enumerate(devices):
        part = tuple(jax.device_put(v[i * size : (i + 1) * size], dev) for v in vals)
        sc, t = jax.device_put((scene, ts), dev)
        outs.append(local(part, sc, getters, fn, config, t, batch_size))
    outs = jax.block_until_ready(outs)
    return jtu.tree_map(lambda *xs: np.concatenate([np.asarray(x) for x in xs]), *outs)


# --------------------------------------------------------------------------------------
# Checking the members before anything compiles


def _check_inits(obj) -> list:
    """The `__check_init__` methods an equinox Module ran when it was built."""
    return [
        c.__dict__["__check_init__"]
        for c in type(obj).__mro__
        if "__check_init__" in c.__dict__
    ]


def _static_field(scene, name):
    """`(owner, field, path)` of the one static (structure) field that `name` names
    (`"k"`, `"model.k"`, `"DisplacementString.k"`), or None."""
    hits = []

    def walk(obj, path):
        if isinstance(obj, eqx.Module):
            for f in dataclasses.fields(obj):
                p = f"{path}.{f.name}" if path else f.name
                if f.metadata.get("static", False):
                    if name in (f.name, p, f"{type(obj).__name__}.{f.name}"):
                        hits.append((obj, f.name, p))
                else:
                    walk(getattr(obj, f.name, None), p)
        elif isinstance(obj, (tuple, list)):
            for i, v in enumerate(obj):
                walk(v, f"{path}[{i}]")

    walk(scene, "")
    return hits[0] if len(hits) == 1 else None


def _refuse_structure(scene, name, values):
    """Raise for a swept name that is a static field (a number of elements, a
    formulation switch): first for a member its own constructor would refuse
    (member index, value, valid range), else because one compiled sweep cannot vary
    structure. Returns quietly when `name` is no static field."""
    hit = _static_field(scene, name) if isinstance(name, str) else None
    if hit is None:
        return
    owner, field, path = hit
    a = np.asarray(values, dtype=object)
    for i, x in enumerate(a.ravel().tolist()):
        if isinstance(x, float) and x.is_integer():
            x = int(x)
        member = copy.copy(owner)
        object.__setattr__(member, field, x)
        try:
            for check in _check_inits(member):
                check(member)
        except ValueError as e:
            where = np.unravel_index(i, a.shape) if a.ndim > 1 else i
            raise ValueError(
                f"sweep `values[{name!r}]` member {where} = {x!r} is invalid: {e}"
            ) from None
    raise ValueError(
        f"`values`: {name!r} ({path}) is structure of {type(owner).__name__} (a "
        "static field: it sets the shapes or the equations), which one compiled "
        "sweep cannot vary; loop over it in Python and sweep array parameters, "
        "e.g. " + ", ".join(repr(n) for n in parameter_names(scene)[:4]) + "."
    )


def _check_members(scene, getters, arrays, grid, shape):
    """Validate every member as its constructors would, before anything compiles.

    A member replaces leaves of the scene with `eqx.tree_at`, which runs no
    `__check_init__`: here each Module that holds a swept leaf (and each Module
    above it, up to the model or effect: a hull's length bounds the model's
    fairlead positions) runs its checks with each member's values. A refused member
    raises a ValueError naming the parameter, the member's index and value, and the
    constructor's message (the valid range).
    """
    nodes = {}  # path of a Module above a swept leaf -> indices of its leaves
    for j, g in enumerate(getters):
        for k in range(len(g.path)):
            prefix = g.path[:k]
            # The scene's own checks read the structure only (shapes, kinds of
            # effects), except for the time span: run them for t0/t1 alone.
            if k == 0 and len(g.path) > 1:
                continue
            nodes.setdefault(prefix, []).append(j)
    for prefix, idx in nodes.items():
        node = _follow(scene, prefix)
        if not isinstance(node, eqx.Module):
            continue
        checks = _check_inits(node)
        if not checks:
            continue
        rel = [getters[j].path[len(prefix) :] for j in idx]
        dtypes = [np.asarray(getters[j](scene)).dtype for j in idx]
        if grid:
            axes = np.meshgrid(*[np.arange(arrays[j].size) for j in idx], indexing="ij")
            rows = np.stack([a.ravel() for a in axes], axis=1)
        else:
            n = arrays[idx[0]].size
            rows = np.repeat(np.arange(n)[:, None], len(idx), axis=1)
        seen = set()
        for row in rows:
            vals = tuple(arrays[j].ravel()[r] for j, r in zip(idx, row))
            key = tuple(float(v) for v in vals)
            if key in seen:
                continue
            seen.add(key)
            member = eqx.tree_at(
                lambda n: [_follow(n, r) for r in rel],
                node,
                [as_array(v, d) for v, d in zip(vals, dtypes)],
            )
            try:
                for check in checks:
                    check(member)
            except ValueError as e:
                where = ", ".join(
                    f"`values[{getters[j].label!r}]` member "
                    f"{_index(r, arrays[j].shape if grid else shape)} = {show(v)}"
                    for j, r, v in zip(idx, row, vals)
                )
                raise ValueError(f"sweep {where} is invalid: {e}") from None


def _index(i, shape):
    """A flat index as the user's index into an array of `shape`."""
    if len(shape) <= 1:
        return int(i)
    return tuple(int(k) for k in np.unravel_index(int(i), shape))


AUTO_MEMBERS_PER_CORE = 16
"""`processes="auto"` uses every core for sweeps of at least this many members per
core (fewer do not pay for starting the workers: docs/performance.md, "Sweeps")."""


def _check_devices(devices):
    if isinstance(devices, str):
        if devices != "auto":
            raise ValueError(
                "`devices` must be 'auto', 1, None or a list of jax devices; got "
                f"{devices!r}."
            )
        return
    if devices is None or (isinstance(devices, int) and devices == 1):
        return
    if (
        isinstance(devices, (list, tuple))
        and devices
        and all(isinstance(d, jax.Device) for d in devices)
    ):
        return
    raise ValueError(
        f"`devices` must be 'auto', 1, None or a list of jax devices; got {devices!r}."
    )


def _on_devices(local, arrays, mine, scene, getters, fn, config, ts, batch_size,
                devices, order):  # fmt: skip
    """The members `mine` on this process's devices: one shard per device (GPUs
    side by side). Returns (outputs in the order of `mine`, devices used)."""
    if devices == "auto":
        devices = jax.local_devices()
    elif devices is None or devices == 1:
        devices = jax.local_devices()[:1]
    devices = list(devices)
    m = len(mine)
    n_dev = max(1, min(len(devices), math.ceil(m / batch_size)))
    devices = devices[:n_dev]
    n_pad = math.ceil(m / (n_dev * batch_size)) * n_dev * batch_size
    # Pad by repeating the last member (dropped again below).
    idx = np.concatenate([np.arange(m), np.full(n_pad - m, m - 1)])
    if n_dev > 1 and order == "sort":
        # Contiguous blocks go to the devices: interleave whole groups, so that
        # each device gets members from across the range (similar total work per
        # device) in the groups they have everywhere else.
        groups = idx.reshape(-1, n_dev, batch_size)
        idx = groups.transpose(1, 0, 2).ravel()
    vals = tuple(jnp.asarray(a[mine][idx]) for a in arrays)
    if n_dev > 1:
        out = _sweep_devices(
            local, vals, scene, getters, fn, config, ts, batch_size, devices
        )
    else:
        # a later process runs the saved program without tracing it
        # (`jaxstring._programs`), as the worker processes run the chunk program
        args = (vals, scene, getters, fn, config, ts, batch_size)
        out = _programs.call_or_jit(local, local, *args)
    out = jax.block_until_ready(out)
    # Each member's position in the padded batch: its first occurrence.
    where = np.empty(m, dtype=np.int64)
    where[idx[::-1]] = np.arange(n_pad)[::-1]
    return jtu.tree_map(lambda x: np.asarray(x)[where], out), n_dev


CPU_GROUP = 16
"""`batch_size="auto"` on a CPU: groups of this many members (measured:
docs/performance.md, "Sweeps")."""

GPU_ONE_GROUP = 4096
"""`batch_size="auto"` on a GPU: up to this many members per device run as one
group; more are grouped to fit the device's memory (`jaxstring._distribute.
fit_group`)."""


def _group_size(batch_size, n, local, arrays, scene, getters, fn, config, ts,
                devices) -> int:  # fmt: skip
    """The members' group size: `batch_size`, all `n` for None, and for "auto"
    `CPU_GROUP` on a CPU, on a GPU all of a device's members or as many as its free
    memory holds."""
    if batch_size is None:
        return n
    if batch_size != "auto":
        return min(batch_size, n)
    if jax.default_backend() == "cpu":
        return min(CPU_GROUP, n)
    devs = jax.local_devices() if devices == "auto" else list(devices or [])[:1]
    devs = devs or jax.local_devices()[:1]
    per_device = math.ceil(n / len(devs))
    if per_device <= GPU_ONE_GROUP:
        return per_device
    vals = tuple(jnp.asarray(a) for a in arrays)
    args = (vals, scene, getters, fn, config, ts, per_device)  # one vmap a probe
    return _distribute.fit_group(local, args, per_device, devs[0])


def _status(code: int, reason: str | None) -> str:
    """A member's status: "success", the solver's failure message, or why its
    worker process failed."""
    if code == 0:
        return "success"
    if code == _distribute.WORKER_FAILED:
        return f"worker process failed: {reason or 'in another process'}"
    from ._solvers.diffrax_compat import code_message

    return code_message(code)


def _workers(processes, executor, members: int) -> int:
    """The worker processes of this host a sweep of `members` uses: `processes`,
    or with "auto" the host's cores where the members are many enough to pay for
    the workers' start (and the default backend is the CPU: GPUs are used by the
    devices of this process)."""
    if executor is not None:
        return 0
    if processes != "auto":
        return int(processes)
    if jax.default_backend() != "cpu":
        return 1
    cores = _distribute.host_cores()
    return cores if members >= AUTO_MEMBERS_PER_CORE * cores else 1


@single_blas_thread
def sweep(
    scene: Scene,
    values: dict,
    fn: Callable | None = None,
    *,
    grid: bool = False,
    devices="auto",
    batch_size="auto",
    order: str = "given",
    mode: str = "vmap",
    fallback: bool = True,
    processes="auto",
    executor=None,
    config: SolveConfig | None = None,
    **options,
) -> SweepResult:
    """Simulate `scene` for a batch or grid of parameter values in one compiled call.

    **Arguments:**

    - `scene`: the base scene; every leaf not swept keeps its value.
    - `values`: dict name -> values, with names as in `fit` (`"alpha"`, `"EA"`,
      `"KelvinVoigt.alpha"`, `"model.EA"`, or a callable `lambda s: ...` as key).
      A batch (`grid=False`): arrays of one common shape, one member per entry. A
      grid (`grid=True`): 1-d arrays, one member per combination (axes in the
      order of the dict). Each member is checked as the constructors of the
      Modules holding the swept leaves check their arguments (a stiffness > 0, a
      finite damping constant, t1 > t0, ...), before anything compiles: a refused
      member raises a ValueError naming the parameter, the member's index and
      value, and the valid range. Structure (an int or str field such as the
      number of elements `k`) cannot be swept: loop over it in Python.
    - `fn`: `fn(traj, scene) -> pytree of arrays` evaluated on each member's
      `Trajectory` inside the compiled call (e.g. a period, the maximum tension);
      default: all observables `traj.obs`. It is part of the compiled program's
      key by its code and the objects it captures: a lambda written anew in the
      same place reuses the compiled sweep; one capturing other objects compiles
      its own.
    - `config`: the `SolveConfig` of every member's solve (default:
      `SolveConfig.default("sweep")`); `options`: its fields as shortcuts
      (`solver`, `rtol`, `atol`, `ts`, `n_save`, `dt0`, `newton_rtol`,
      `newton_atol`, `max_steps`, `project`, `step_control`); `ts` is shared by all
      members (default: `n_save` points over the base scene's span).
    - `devices`: `"auto"` (all local devices of the default backend), a list of
      devices, or 1 / None (no sharding). Members are padded to a multiple of the
      device count. GPUs run their shards at the same time; XLA:CPU devices one
      after the other (use `processes` for the cores of a CPU host).
    - `processes`: `"auto"` (default: every core of a CPU host when there are at
      least `AUTO_MEMBERS_PER_CORE` members per core, else this process alone; on
      a GPU host the GPUs; where the pool is not running and its workers ran this
      program's chunks for less than they take to start, this process runs them:
      `jaxstring._distribute.short_here`), or the number of worker processes:
      the members go in chunks to jaxstring's own pool of spawned processes (kept
      for later sweeps), which run the program this process traced once
      (`jaxstring._distribute`).
      A pool with one worker per core of this process binds each worker to a
      core of its own (docs/performance.md, "Sweeps on every core and every
      GPU").
    - `executor`: any `concurrent.futures.Executor` whose workers can import
      jaxstring (a `ProcessPoolExecutor`, a Dask cluster's executor) to run the
      chunks instead. A worker that dies loses no member: its chunks are run again
      once; a chunk that fails twice gives its members the status "worker process
      failed" (result code -1). In a `jax.distributed` job (several processes,
      each calling `jax.distributed.initialize`) every process runs its block of
      the members and receives every member's result.
    - `batch_size`: run members in groups of this size (a vmap each, inside
      `lax.map`); `"auto"` (default): `CPU_GROUP` (16) on a CPU (measured:
      docs/performance.md, "Sweeps"), on a GPU all of a device's members, or as
      many as its free memory holds; None: all members in one group. The members
      are padded to whole groups, so that every member runs in a group of the
      same size wherever it runs (this process, a device, a worker, a distributed
      process) and gets the same result.
    - `order`: `"given"`, or `"sort"` to group members by their parameter values
      (lexicographically, in the order of `values`) -- results come back in the
      given order either way.
    - `mode`: `"vmap"` (default): each member has its own solve (its own step
      sequence), vmapped: the members' results equal those of `simulate` calls
      to rounding; with `solver="bdf"` the fastest mode (docs/performance.md, "A
      sweep against a peer loop").
      `"lockstep"`: all members (of a device) are integrated as one
      ODE on the stacked states, with one shared step sequence accepted only
      when every member's own error norm is within the tolerance, and
      block-diagonal (per-member) Newton linear algebra. Much faster on a CPU
      (docs/performance.md, "Sweeps"); each member is then at least as
      accurate as its own solve, but not bitwise equal to it (differences of the
      order of the tolerance). Supports `solver` "kvaerno3/4/5",
      "implicit_euler", "tsit5", "dopri5"; and the fixed-step "implicit_euler_fixed",
      "theta", "trapezoid" for node-major states (every member then takes its own
      solve's steps: with `newton_rtol = newton_atol = 1e-10` the members equal
      their `simulate` calls to rounding); not for sweeping `t0`/`t1`.
      With lockstep, small groups (`batch_size` 4, `order="sort"`) serve best:
      the per-member cost of the batched Jacobian and factorisation grows with
      the group, and a shared step sequence is set by its hardest member.
    - `fallback`: lockstep only: when the shared solve fails (a failure of any
      member stops it), re-run the members with `mode="vmap"`, so that each gets
      its own status and the others are intact (`SweepResult.mode` says so).

    **Returns:** a `SweepResult`; `ok` marks the members whose solve succeeded (a
    failure, e.g. `max_steps` reached for one stiff member, leaves the others intact).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if not isinstance(values, dict) or not values:
        raise ValueError(
            "`values` must be a non-empty dict: name -> array of values; got "
            f"{values!r}."
        )
    if fn is not None and not callable(fn):
        raise ValueError(
            f"`fn` must be callable, fn(traj, scene) -> pytree of arrays; got {fn!r}."
        )
    check_choice("order", order, ("given", "sort"))
    check_choice("mode", mode, ("vmap", "lockstep"))
    _distribute.check_workers(processes, executor)
    config = solver_for(solve_config("sweep", config, **options), scene)
    config.check_scene(scene)
    solver = config.solver
    if batch_size not in (None, "auto"):
        check_int("batch_size", batch_size, 1)
    _check_devices(devices)
    getters = []
    for name, v in values.items():
        try:
            getters.append(resolve(scene, name))
        except ValueError:
            _refuse_structure(scene, name, v)
            raise
    getters = tuple(getters)
    paths = [g.path for g in getters]
    twice = [g.label for g in getters if paths.count(g.path) > 1]
    if twice:
        raise ValueError(
            f"`values` names the same leaf twice ({', '.join(map(repr, twice))}); "
            "valid: each parameter once."
        )
    arrays = []
    for g, v in zip(getters, values.values()):
        try:
            arrays.append(np.asarray(v, dtype=np.float64))
        except (TypeError, ValueError):
            raise ValueError(
                f"`values[{g.label!r}]` must be an array of numbers; got {v!r}."
            ) from None
    for g, a in zip(getters, arrays):
        if np.shape(g(scene)) != ():
            raise ValueError(
                f"`values`: {g.label!r} is not a scalar leaf; sweep scalar parameters."
            )
        if mode == "lockstep" and (g(scene) is scene.t0 or g(scene) is scene.t1):
            raise ValueError(
                f"`values`: {g.label!r} is the time span, which members of a "
                "lockstep sweep share; use mode='vmap'."
            )
    if mode == "lockstep" and not (
        isinstance(solver, str)
        and (solver in LOCKSTEP_SOLVERS or solver in LOCKSTEP_FIXED)
    ):
        raise ValueError(
            "`solver` for mode='lockstep' must be one of "
            f"{', '.join(list(LOCKSTEP_SOLVERS) + list(LOCKSTEP_FIXED))}; got "
            f"{solver!r} (or use mode='vmap')."
        )
    if mode == "lockstep" and solver in LOCKSTEP_FIXED and jnp.ndim(scene.y0) != 2:
        raise ValueError(
            f"mode='lockstep' with solver {solver!r} needs a node-major state "
            f"(n_nodes, b); got shape {jnp.shape(scene.y0)}."
        )
    if grid:
        if any(a.ndim != 1 for a in arrays):
            raise ValueError(
                "with `grid=True`, each entry of `values` must be 1-d; got "
                + ", ".join(f"{g.label}: {a.shape}" for g, a in zip(getters, arrays))
            )
        shape = tuple(a.size for a in arrays)
    else:
        shape = arrays[0].shape
        if any(a.shape != shape for a in arrays):
            raise ValueError(
                "`values` arrays must have one common shape (or use grid=True); got "
                + ", ".join(f"{g.label}: {a.shape}" for g, a in zip(getters, arrays))
            )
    if math.prod(shape) == 0:
        raise ValueError(f"`values` holds no members (shape {shape}).")
    _check_members(scene, getters, arrays, grid, shape)
    for g, a in zip(getters, arrays):
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            i = bad[0]
            raise ValueError(
                f"`values[{g.label!r}]` member {_index(i, a.shape)} = "
                f"{show(a.ravel()[i])}: sweep values must be finite numbers."
            )
    if grid:
        arrays = [m.ravel() for m in np.meshgrid(*arrays, indexing="ij")]
    else:
        arrays = [a.ravel() for a in arrays]
    n = arrays[0].size
    ts = config.save_times(scene.t0, scene.t1)
    config = config.replace(ts=None)
    fn = _default_fn if fn is None else fn

    perm = np.lexsort(arrays[::-1]) if order == "sort" else np.arange(n)
    # Members run in groups of `group` everywhere -- in this process, on each
    # device, in each worker's chunk, in each process's block -- padded with copies
    # of the last member, so that a member's result does not depend on where it ran.
    local_fn = _sweep_lockstep if mode == "lockstep" else _sweep_local
    group = _group_size(batch_size, n, local_fn, arrays, scene, getters, fn, config,
                        ts, devices)  # fmt: skip
    # A jax.distributed job: this process runs its block of the (ordered) members.
    start, block = (0, n)
    if jax.process_count() > 1:
        start, block = _distribute.process_block(n, group)
    mine = perm[start : start + block]
    workers = _workers(processes, executor, len(mine))
    ran = {"processes": workers if executor is None else 0}

    def run(local):
        if len(mine) == 0:
            # An empty block of a distributed job: one member's run, to give the
            # gathered results their structure, then no rows.
            out, _, n_dev = run_block(local, perm[-1:])
            return jtu.tree_map(lambda x: np.asarray(x)[:0], out), {}, n_dev
        return run_block(local, mine)

    def run_block(local, mine):
        if executor is not None or workers > 1:
            per = len(mine) / (4 * workers if executor is None else 8)
            chunk = math.ceil(max(1, math.ceil(per)) / group) * group
            args = (tuple(a[mine] for a in arrays), scene, getters, fn, config, ts)
            # with "auto", chunks that ran shortly in an earlier pool run here
            out, failed, used = _distribute.local_run(
                executor, workers, local, args + (group,), len(arrays), chunk,
                adaptive=processes == "auto",
            )  # fmt: skip
            if executor is None:
                ran["processes"] = used
            return out, failed, 1
        out, n_dev = _on_devices(local, arrays, mine, scene, getters, fn, config, ts,
                                 group, devices, order)  # fmt: skip
        return out, {}, n_dev

    t = time.perf_counter()
    result, failed, n_dev = run(local_fn)
    used = mode
    if mode == "lockstep" and fallback and result is not None:
        if not np.all(np.asarray(result[1]) == 0):
            result, failed, n_dev = run(_sweep_local)
            used = "lockstep, then vmap"
    if result is not None:
        result = jtu.tree_map(np.asarray, result)
        codes = result[1].copy()
        for m in failed:
            codes[m] = _distribute.WORKER_FAILED
        result = (result[0], codes, result[2])
    if jax.process_count() > 1:
        result = _distribute.gather_blocks(result, n, block)
    elapsed = time.perf_counter() - t

    out, codes, stats = result
    # Back from the members' run order (`perm`) to the given order.
    where = np.empty(n, dtype=np.int64)
    where[perm] = np.arange(n)
    take = lambda x: np.asarray(x)[where].reshape(shape + np.shape(x)[1:])
    out = jtu.tree_map(take, out)
    codes = take(codes)
    stats = {k: take(v) for k, v in stats.items()}
    ok = codes == 0
    reasons = {int(where[start + m]): r for m, r in failed.items()}
    status = [_status(int(c), reasons.get(i)) for i, c in enumerate(codes.ravel())]
    return SweepResult(
        values={g.label: a.reshape(shape) for g, a in zip(getters, arrays)},
        out=out,
        ok=ok,
        result=codes,
        status=status,
        stats=stats,
        shape=shape,
        n_devices=n_dev,
        time=elapsed,
        mode=used,
        processes=ran["processes"],
    )
