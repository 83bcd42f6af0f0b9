"""sweep: evaluate a scene over a batch or grid of parameter values in one call.

Each member is the scene with some array leaves replaced (by name or path, as in
`fit`); all members are integrated by one `jax.vmap` of the same solve inside one
`eqx.filter_jit`. Failures do not abort the sweep: the solve never throws, and each
member carries its own diffrax result code (`ok`, `status`).

Why plain vmap is not enough on a CPU: a vmapped adaptive solve runs its members in
lockstep -- every loop iteration advances all members, each with its own step size,
until the slowest is done -- so the cost is (largest number of steps) x (members),
against the sum of the steps for a loop. What helps (measured in
experiments/sweep_speed.py):

* sharding: with several devices (``XLA_FLAGS=--xla_force_host_platform_device_count=2``
  makes one per CPU core), the members are split into one shard per device, each
  committed to its device and dispatched asynchronously: each device runs its own
  solver loop, with no synchronisation between devices. (`jax.shard_map` would be
  the one-program form, but lineax's structure check fails on the manual-mesh
  shapes inside it, and a jit over `NamedSharding` inputs turns the batched loop
  predicate into a cross-device reduction every step.)
* grouping (`batch_size`): members run in groups of `batch_size` (vmap inside a
  `lax.map`), so a slow member only holds up its own group; with `order="sort"` members
  are grouped by their parameter values, so that similar members (similar stiffness,
  similar step sequences) share a group.
"""

import math
import time
from collections.abc import Callable
from typing import Any

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ._fit import SolveConfig, resolve, solve
from ._scene import Scene
from ._validate import check_choice, check_int


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
    - `time`: seconds for the call (compilation included on a first call; a second
      call with the same structure reuses the compiled sweep).
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


def _default_fn(traj, scene):
    del scene
    return traj.obs


def _member(vals, scene, getters, fn, config, ts):
    sc = eqx.tree_at(
        lambda s: [g(s) for g in getters],
        scene,
        [v.astype(g(scene).dtype) for v, g in zip(vals, getters)],
    )
    traj = solve(sc, config, ts)
    stats = {k: v for k, v in traj.stats.items() if k != "max_steps"}
    return fn(traj, sc), traj.result._value, stats


def _run_group(vals, scene, getters, fn, config, ts, batch_size):
    member = lambda v: _member(v, scene, getters, fn, config, ts)
    if batch_size is None or batch_size >= vals[0].shape[0]:
        return jax.vmap(member)(vals)
    return jax.lax.map(member, vals, batch_size=batch_size)


@eqx.filter_jit
def _sweep_local(vals, scene, getters, fn, config, ts, batch_size):
    return _run_group(vals, scene, getters, fn, config, ts, batch_size)


def _sweep_devices(vals, scene, getters, fn, config, ts, batch_size, devices):
    """Split the members over `devices` and run the shards concurrently.

    Each shard is committed to its device (`jax.device_put`); JAX dispatches the
    calls asynchronously, so the devices (CPU cores with
    ``--xla_force_host_platform_device_count``) integrate their shards at the same
    time, each with its own solver loop (no lockstep across devices).
    """
    n_dev = len(devices)
    size = vals[0].shape[0] // n_dev
    outs = []
    for i, dev in enumerate(devices):
        part = tuple(jax.device_put(v[i * size : (i + 1) * size], dev) for v in vals)
        sc, t = jax.device_put((scene, ts), dev)
        outs.append(_sweep_local(part, sc, getters, fn, config, t, batch_size))
    return jtu.tree_map(lambda *xs: np.concatenate([np.asarray(x) for x in xs]), *outs)


def sweep(
    scene: Scene,
    values: dict,
    fn: Callable | None = None,
    *,
    grid: bool = False,
    solver="kvaerno5",
    rtol: float = 1e-6,
    atol: float = 1e-6,
    ts=None,
    n_save: int = 201,
    dt0=None,
    max_steps: int = 200_000,
    project: bool = True,
    devices="auto",
    batch_size: int | None = None,
    order: str = "given",
) -> SweepResult:
    """Simulate `scene` for a batch or grid of parameter values in one compiled call.

    **Arguments:**

    - `scene`: the base scene; every leaf not swept keeps its value.
    - `values`: dict name -> values, with names as in `fit` (`"alpha"`, `"EA"`,
      `"KelvinVoigt.alpha"`, `"model.EA"`, or a callable `lambda s: ...` as key).
      A batch (`grid=False`): arrays of one common shape, one member per entry. A
      grid (`grid=True`): 1-d arrays, one member per combination (axes in the
      order of the dict).
    - `fn`: `fn(traj, scene) -> pytree of arrays` evaluated on each member's
      `Trajectory` inside the compiled call (e.g. a period, the maximum tension);
      default: all observables `traj.obs`.
    - `solver`, `rtol`, `atol`, `ts`, `n_save`, `dt0`, `max_steps`, `project`: as for
      `jaxstring.simulate`; `ts` is shared by all members (default: `n_save` points
      over the base scene's span).
    - `devices`: `"auto"` (all devices of the default backend), a list of devices, or
      1 / None (no sharding). Members are padded to a multiple of the device count.
    - `batch_size`: run members in groups of this size (vmap inside `lax.map`);
      None: all members of a device in one vmap.
    - `order`: `"given"`, or `"sort"` to group members by their parameter values
      (lexicographically, in the order of `values`) -- results come back in the
      given order either way.

    **Returns:** a `SweepResult`; `ok` marks the members whose solve succeeded (a
    failure, e.g. `max_steps` reached for one stiff member, leaves the others intact).
    """
    if not isinstance(scene, Scene):
        raise ValueError(f"`scene` must be a jaxstring Scene; got {type(scene)}.")
    if not isinstance(values, dict) or not values:
        raise ValueError("`values` must be a non-empty dict: name -> array of values.")
    check_choice("order", order, ("given", "sort"))
    if batch_size is not None:
        check_int("batch_size", batch_size, 1)
    getters = tuple(resolve(scene, name) for name in values)
    if len({g.path for g in getters}) != len(getters):
        raise ValueError("`values` names the same leaf twice.")
    arrays = [np.asarray(v, dtype=np.float64) for v in values.values()]
    for g, a in zip(getters, arrays):
        if np.shape(g(scene)) != ():
            raise ValueError(
                f"`values`: {g.label!r} is not a scalar leaf; sweep scalar parameters."
            )
        if not np.all(np.isfinite(a)):
            raise ValueError(f"`values[{g.label!r}]` must be finite.")
    if grid:
        if any(a.ndim != 1 for a in arrays):
            raise ValueError("with `grid=True`, each entry of `values` must be 1-d.")
        shape = tuple(a.size for a in arrays)
        arrays = [m.ravel() for m in np.meshgrid(*arrays, indexing="ij")]
    else:
        shape = arrays[0].shape
        if any(a.shape != shape for a in arrays):
            raise ValueError(
                "`values` arrays must have one common shape (or use grid=True); got "
                + ", ".join(f"{g.label}: {a.shape}" for g, a in zip(getters, arrays))
            )
        arrays = [a.ravel() for a in arrays]
    n = arrays[0].size
    if n == 0:
        raise ValueError("`values` holds no members.")
    config = SolveConfig(
        solver=solver,
        rtol=rtol,
        atol=atol,
        n_save=n_save,
        dt0=dt0,
        max_steps=max_steps,
        project=project,
    )
    fn = _default_fn if fn is None else fn
    if ts is None:
        ts = jnp.linspace(scene.t0, scene.t1, n_save)
    ts = jnp.asarray(ts, dtype=jnp.float64)

    perm = np.lexsort(arrays[::-1]) if order == "sort" else np.arange(n)
    if devices == "auto":
        devices = jax.devices()
    elif devices is None or devices == 1:
        devices = jax.devices()[:1]
    devices = list(devices)
    n_dev = max(1, min(len(devices), n))
    devices = devices[:n_dev]
    n_pad = math.ceil(n / n_dev) * n_dev
    # Pad by repeating the last member (dropped again below).
    idx = np.concatenate([perm, np.full(n_pad - n, perm[-1], dtype=perm.dtype)])
    if n_dev > 1 and order == "sort":
        # Contiguous blocks go to the devices: interleave so that each device gets
        # members from across the range (similar total work per device).
        idx = idx.reshape(-1, n_dev).T.ravel()
    vals = tuple(jnp.asarray(a[idx]) for a in arrays)

    t = time.perf_counter()
    if n_dev > 1:
        out, codes, stats = _sweep_devices(
            vals, scene, getters, fn, config, ts, batch_size, devices
        )
    else:
        out, codes, stats = _sweep_local(
            vals, scene, getters, fn, config, ts, batch_size
        )
    jax.block_until_ready((out, codes, stats))
    elapsed = time.perf_counter() - t

    # Position of each member in the (permuted, padded) batch: its first occurrence.
    where = np.empty(n, dtype=np.int64)
    where[idx[::-1]] = np.arange(n_pad)[::-1]
    take = lambda x: np.asarray(x)[where].reshape(shape + np.shape(x)[1:])
    out = jtu.tree_map(take, out)
    codes = take(codes)
    stats = {k: take(v) for k, v in stats.items()}
    ok = codes == 0
    status = [
        "success" if c == 0 else (dfx.RESULTS._index_to_message[int(c)] or "failure")
        for c in codes.ravel()
    ]
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
    )
