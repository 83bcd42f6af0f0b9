"""Where the members of a sweep run: the devices of this process, worker processes
over this host's cores, and the processes of a `jax.distributed` job.

* One XLA:CPU process runs one solver loop at a time, so the cores of a CPU host
  are used by processes: the parent traces the chunk program once, exports it
  (`jax.export`) and hands it with each chunk of members to the workers of a
  `concurrent.futures` executor -- jaxstring's own spawn pool (kept for later
  sweeps) or any executor the user passes (a Dask cluster's, say). A worker only
  compiles and runs (`jaxstring._worker`); the compilation is shared through the
  persistent compilation cache. A worker that dies loses no member: the chunks it
  held are run again in a fresh pool, and a chunk that fails twice comes back
  with the status `WORKER_FAILED`.
* A `jax.distributed` job (N processes started by SLURM, Open MPI or by hand,
  each calling `jax.distributed.initialize`) splits the members into one block
  per process; each process runs its block on its own devices or workers, and
  every process gathers every member's result (`process_allgather`).
* GPUs of one process run their shards side by side (`jaxstring._sweep`).

`least_squares` and `fit` evaluate their experiments in the same pools
(`ExperimentPrograms`: one exported program and one task per experiment); in a
`jax.distributed` job each process evaluates its share of the experiments and every
process gathers all of them, so that each runs the same iteration.
"""

import atexit
import concurrent.futures as cf
import contextlib
import dataclasses
import hashlib
import math
import multiprocessing
import os
import pathlib
import pickle
import sys
import time

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np

from . import _executables as executables, _programs, _worker
from ._jit import cpu_compiler_options
from ._validate import check_int


WORKER_FAILED = -1
"""Result code of a member whose chunk failed in a worker process twice."""


def host_cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def check_workers(processes, executor) -> None:
    """Refuse bad `processes` ("auto" or an int >= 1) and `executor` (a
    `concurrent.futures.Executor`, not given with `processes`) by name."""
    if processes != "auto":
        check_int("processes", processes, 1)
    if executor is not None:
        if not isinstance(executor, cf.Executor):
            raise ValueError(
                "`executor` must be a concurrent.futures.Executor (a "
                "ProcessPoolExecutor, a Dask client's get_executor(), ...); got "
                f"{type(executor).__name__}: {executor!r}."
            )
        if processes != "auto":
            raise ValueError(
                "give `processes` or `executor`, not both (an executor has its own "
                f"workers); got processes={processes!r}."
            )


def experiment_workers(processes, executor, n_experiments: int, on_cpu: bool) -> int:
    """Worker processes of this host for `n_experiments` experiments of a fit:
    `processes`, or with "auto" one per experiment up to the host's cores where
    there are several and their solves run on a CPU (`on_cpu`); 0 for a user's
    executor."""
    if executor is not None:
        return 0
    if processes != "auto":
        return int(processes)
    # In a jax.distributed job this process evaluates its share of them.
    mine = math.ceil(n_experiments / jax.process_count())
    if not on_cpu or mine < 2:
        return 1
    return min(host_cores(), mine)


def _flat(fn, args):
    """`fn(*args)` as a function of the arrays of `args` alone (a list), and those
    arrays: (flat function, leaves, treedef, static parts)."""
    dynamic, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jtu.tree_flatten(dynamic)

    def flat(*xs):
        return fn(*eqx.combine(jtu.tree_unflatten(treedef, xs), static))

    return flat, leaves, treedef, static


def export_chunk(fn, args):
    """`fn(*args)` traced once and exported: (key, pickled program, leaves,
    outputs), the arrays of `args` as the program's inputs (everything else
    compiled in) and `outputs` the output structure (shapes and dtypes)."""
    flat, leaves, treedef, static = _flat(fn, args)
    avals = tuple(jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves)
    try:
        cache_key = (fn, treedef, static, avals)
        hash(cache_key)
    except TypeError:  # a static part that cannot be hashed: export every time
        cache_key = None
    if cache_key is not None and cache_key in _EXPORTED:
        return (*_EXPORTED[cache_key][:2], leaves, _EXPORTED[cache_key][2])
    # A later process reads the traced program from the program folder.
    exported = _programs.saved_export(fn, static, treedef, leaves)
    if exported is None:
        jitted = jax.jit(flat, compiler_options=cpu_compiler_options())
        exported = jax.export.export(jitted, platforms=("cpu",))(*avals)
    # The private `_get_vjp` (a closure, not picklable) serves differentiation of
    # the loaded program only, which a sweep does not do.
    data = pickle.dumps(dataclasses.replace(exported, _get_vjp=None))
    outputs = jtu.tree_unflatten(exported.out_tree, exported.out_avals)
    # keyed by what the program computes (its module, trees and shapes), which a
    # program read back from the program folder shares with the one traced
    # (their pickles differ): a worker's saved executable serves both
    h = hashlib.sha256(exported.mlir_module_serialized)
    for part in (exported.in_tree, exported.out_tree, exported.in_avals,
                 exported.out_avals, exported.platforms):  # fmt: skip
        h.update(repr(part).encode())
    key = h.hexdigest()[:32]
    if cache_key is not None:
        _EXPORTED[cache_key] = (key, data, outputs)
    return key, data, leaves, outputs


_EXPORTED = {}  # (fn, structure, static parts, shapes) -> exported chunk program


_POOL = {"executor": None, "workers": 0}


PIN_WORKERS = True
"""A pool with one worker per core of this process (the default of `processes=
"auto"`) runs each worker on a core of its own (`pinned_cores`)."""


def pinned_cores(workers: int):
    """The cores the workers of a pool of `workers` are bound to, one each: this
    process's cores where there are as many workers as cores and `PIN_WORKERS`;
    else None (the system places them). A worker then keeps its core and its
    caches, and XLA's threads of one worker do not displace another: measured
    in docs/performance.md, "Sweeps on every core and every GPU"."""
    if not PIN_WORKERS or not hasattr(os, "sched_getaffinity"):
        return None
    cores = sorted(os.sched_getaffinity(0))
    return cores if workers == len(cores) > 1 else None


def process_pool(workers: int) -> cf.ProcessPoolExecutor:
    """jaxstring's own pool of `workers` spawned processes (kept for later sweeps;
    one fork of a process running JAX's threads could deadlock, hence spawn)."""
    if _POOL["executor"] is not None and _POOL["workers"] == workers:
        return _POOL["executor"]
    shutdown_pool()
    cache = jax.config.jax_compilation_cache_dir or None
    context = multiprocessing.get_context("spawn")
    cores = pinned_cores(workers)
    started = context.Value("i", 0) if cores else None
    executor = cf.ProcessPoolExecutor(
        max_workers=workers,
        mp_context=context,
        initializer=_worker.init,
        initargs=(cache, cores, started),
    )
    with _main_not_rerun():  # a worker process starts at a submit with none idle
        for _ in range(workers):
            executor.submit(_worker.ready)
    _POOL["executor"], _POOL["workers"] = executor, workers
    return executor


@contextlib.contextmanager
def _main_not_rerun():
    """Start processes without the parent's `__main__` module.

    A spawned process imports the parent's main script before it runs anything,
    which re-runs a script without an ``if __name__ == "__main__":`` guard (and
    its sweep). jaxstring's workers run exported programs and need nothing from
    it, so the script's path and spec are hidden while they start."""
    main = sys.modules.get("__main__")
    if main is None:
        yield
        return
    saved = {
        k: main.__dict__[k] for k in ("__file__", "__spec__") if k in main.__dict__
    }
    main.__dict__.pop("__file__", None)
    main.__spec__ = None
    try:
        yield
    finally:
        main.__dict__.pop("__spec__", None)
        main.__dict__.update(saved)


def shutdown_pool() -> None:
    """Stop jaxstring's own worker processes (they also stop when Python exits)."""
    if _POOL["executor"] is not None:
        _POOL["executor"].shutdown(wait=True, cancel_futures=True)
    _POOL["executor"], _POOL["workers"] = None, 0


atexit.register(shutdown_pool)


def run_chunks(executor, key, program, chunks, own_pool, timed=None):
    """Run the exported `program` on each chunk's leaves in `executor`: a list with
    each chunk's outputs, or the text of its failure (`run_tasks`). `timed`: a
    saved program's key under which the chunks' median run time in a worker is
    kept for the next sweep (`short_here`)."""
    tasks = [(key, program, c) for c in chunks]
    if timed is None:
        return run_tasks(executor, tasks, own_pool)
    results = run_tasks(executor, tasks, own_pool, run=_worker.run_timed)
    _record_seconds(timed, [r[1] for r in results if not isinstance(r, str)])
    return [r if isinstance(r, str) else r[0] for r in results]


WORKER_START_S = 1.5
"""What starting jaxstring's pool costs a sweep before its workers run, in
seconds: each spawned worker imports JAX and reads the program's executable
(measured in docs/performance.md, "Sweeps on every core and every GPU")."""


def pool_pays(run_s: float, workers: int) -> bool:
    """Whether chunks that ran `run_s` seconds one after the other in a pool's
    worker are worth starting a pool of `workers` for: whether they run longer than
    the pool takes to start. (A pool started now ends them after about
    `WORKER_START_S` + `run_s / workers`; this process, not bound to a core as a
    worker is, runs them slower than a worker does, so their break-even lies near
    `WORKER_START_S` for two workers and below it for more: docs/performance.md,
    "Sweeps on every core and every GPU".)"""
    return workers > 1 and run_s > WORKER_START_S


_RUN_HERE = {"s": 0.0}  # seconds of chunks this process ran in place of a pool


def _seconds_path(saved_key: str):
    folder = _worker.folder()
    if folder is None:
        return None
    machine = executables.machine(_worker.pool_flags())
    return pathlib.Path(folder) / f"{saved_key}.{machine}.chunk_seconds"


def _record_seconds(saved_key: str, seconds: list) -> None:
    target = _seconds_path(saved_key)
    if target is None or not seconds:
        return
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(repr(float(np.median(seconds))))
        os.replace(tmp, target)
    except OSError:
        pass  # not kept: the next sweep goes to the pool


def short_here(saved_key: str | None, n_chunks: int, workers: int) -> bool:
    """Whether `n_chunks` chunks of the saved program `saved_key` ran so shortly in
    an earlier pool's worker that this process had better run them than start a
    pool of `workers` (`pool_pays`; the chunks run here by earlier sweeps count
    too, so that a loop of short sweeps starts the pool once they add up)."""
    target = None if saved_key is None else _seconds_path(saved_key)
    try:
        seconds = float(target.read_text())
    except (AttributeError, OSError, ValueError):
        return False
    return not pool_pays(n_chunks * seconds + _RUN_HERE["s"], workers)


def run_here(key: str, chunks: list):
    """The chunks of program `key` run in this process, one after the other, on the
    executable a pool's worker saved: a list as `run_chunks` gives it; None where
    there is no such executable."""
    compiled = executables.read(_worker.folder(), key, "full", _worker.pool_flags())
    if compiled is None:
        return None
    out = []
    start = time.perf_counter()
    for leaves in chunks:
        try:
            out.append(jax.device_get(compiled(*leaves)))
        except Exception as error:  # noqa: BLE001  (reported as the chunk's failure)
            out.append(f"{type(error).__name__}: {error}")
    _RUN_HERE["s"] += time.perf_counter() - start
    return out


def run_tasks(executor, tasks, own_pool, run=None):
    """Run each task `(key, exported program, leaves)` in `executor` (by `run`,
    default `_worker.run`): a list with each task's outputs, or the text of its
    failure. A worker that dies breaks a process pool and every task in flight
    with it, so the lost tasks are run again in parallel once, and those lost
    again one at a time: a task fails only when it fails on its own. jaxstring's
    own pool (`own_pool`) is started afresh after a break; a user's executor is
    used as it is."""
    run = _worker.run if run is None else run
    results = [None] * len(tasks)

    def attempt(todo):
        nonlocal executor
        if own_pool and _POOL["executor"] is not None and _POOL["executor"]._broken:
            workers = _POOL["workers"]
            shutdown_pool()
            executor = process_pool(workers)
        submit = lambda i: executor.submit(run, *tasks[i])
        with _main_not_rerun() if own_pool else contextlib.nullcontext():
            futures = {submit(i): i for i in todo}
        lost = []
        for future in cf.as_completed(futures):
            i = futures[future]
            try:
                results[i] = future.result()
            except Exception as error:  # noqa: BLE001  (a dead or broken worker)
                lost.append(i)
                results[i] = f"{type(error).__name__}: {error}"
        return sorted(lost)

    lost = attempt(range(len(tasks)))
    if lost:
        lost = attempt(lost)
    for i in lost:
        attempt([i])
    return results


def local_run(executor, workers, fn, args, n_vals, chunk, adaptive=False):
    """The members `args[0]` (a tuple of value arrays, `(n,)` each) in chunks of
    `chunk`, each chunk `fn(chunk values, *args[1:])`, in `executor` (None:
    jaxstring's pool of `workers`). Returns (outputs, failed, workers used) with
    every leaf of the outputs `(n, ...)` in member order, and `failed` a dict
    member index -> reason for members whose chunk failed (their outputs NaN or
    zero). `adaptive` (jaxstring's pool only): where the pool is not running and
    an earlier pool ran the saved program too shortly to pay for starting one,
    this process runs the chunks (`short_here`, `run_here`; 1 worker used)."""
    vals = args[0]
    n = vals[0].shape[0]
    n_chunks = math.ceil(n / chunk)
    pad = n_chunks * chunk - n
    padded = [np.concatenate([v, np.repeat(v[-1:], pad)]) for v in vals]
    parts = [
        tuple(v[i * chunk : (i + 1) * chunk] for v in padded) for i in range(n_chunks)
    ]
    own = executor is None
    first = (parts[0],) + tuple(args[1:])
    # Decided before the program is read, so that a pool starts while this
    # process reads or traces it.
    saved = _programs.saved_key(fn, first) if own else None
    here = adaptive and own and _POOL["workers"] != workers
    here = here and short_here(saved, n_chunks, workers)
    if own and not here:
        process_pool(workers)
    key, program, leaves, outputs = export_chunk(fn, first)
    shared = [np.asarray(x) for x in leaves[n_vals:]]
    chunks = [[np.asarray(v) for v in p] + shared for p in parts]
    results = run_here(key, chunks) if here else None
    used = workers if results is None else 1
    if results is None:
        pool = process_pool(workers) if own else executor
        timed = (saved or _programs.saved_key(fn, first)) if own else None
        results = run_chunks(pool, key, program, chunks, own, timed=timed)
    failed = {}
    out = []
    for i, r in enumerate(results):
        if isinstance(r, str):
            for m in range(i * chunk, min(n, (i + 1) * chunk)):
                failed[m] = r
            r = jtu.tree_map(_failed_like, outputs)
        out.append(r)
    merged = jtu.tree_map(lambda *xs: np.concatenate(xs)[:n], *out)
    return merged, failed, used


class ExperimentPrograms:
    """The experiments of an identification, each `fn(x, *args)` traced once and
    exported, evaluated at the parameters `x` of each step of the calling
    process's iteration: in `executor` (None: jaxstring's pool of `workers`, or
    this process for one worker). In a `jax.distributed` job process p evaluates
    experiments p, p + P, ... and every process gathers every experiment's outputs
    (`process_allgather`), so that all of them run the same iteration.

    A call returns `combine(outputs)` with each experiment's outputs in order; an
    experiment whose evaluation failed twice gives NaN outputs, and `failed` keeps
    its index and the reason."""

    def __init__(self, fn, experiment_args, executor, workers, combine):
        from ._solvers.diffrax_compat import checks_as_nan

        self.executor, self.workers, self.combine = executor, workers, combine
        self.tasks, self.outputs = [], []
        for args in experiment_args:
            with checks_as_nan():
                key, program, leaves, outputs = export_chunk(fn, args)
            self.tasks.append((key, program, [np.asarray(v) for v in leaves[1:]]))
            self.outputs.append(outputs)
        self.failed = {}  # experiment index -> why its evaluation failed

    def __call__(self, x):
        x = np.asarray(x)
        n_proc, me = jax.process_count(), jax.process_index()
        mine = list(range(me, len(self.tasks), n_proc))
        tasks = [(k, p, [x] + rest) for k, p, rest in (self.tasks[i] for i in mine)]
        if self.executor is None and self.workers <= 1:
            results = [_run_here(task) for task in tasks]
        else:
            own = self.executor is None
            pool = process_pool(self.workers) if own else self.executor
            results = run_tasks(pool, tasks, own)
        outs = [None] * len(self.tasks)
        for i, out in zip(mine, results):
            if isinstance(out, str):
                self.failed.setdefault(i, out)
                out = jtu.tree_map(_failed_like, self.outputs[i])
            outs[i] = out
        if n_proc > 1:
            outs = self._gathered(outs, n_proc)
        return self.combine(outs)

    def _gathered(self, outs, n_proc):
        """Every experiment's outputs from the process that evaluated it: one
        vector per process (this process's outputs, zeros elsewhere, and a failure
        flag per experiment), gathered on every process."""
        from jax.experimental import multihost_utils

        flags = [float(i in self.failed) for i in range(len(outs))]
        parts = [np.asarray(flags)]
        for out, shape in zip(outs, self.outputs):
            avals = jtu.tree_leaves(shape)
            leaves = [np.zeros(a.shape) for a in avals] if out is None else out
            for leaf in jtu.tree_leaves(leaves):
                parts.append(np.asarray(leaf, np.float64).ravel())
        rows = np.asarray(multihost_utils.process_allgather(np.concatenate(parts)))
        gathered, at = [], len(outs)
        for i, shape in enumerate(self.outputs):
            row = rows[i % n_proc]
            if row[i] and i not in self.failed:
                self.failed[i] = (
                    f"its evaluation failed in process {i % n_proc} of the "
                    "jax.distributed job"
                )
            leaves, treedef = jtu.tree_flatten(shape)
            values = []
            for aval in leaves:
                size = math.prod(aval.shape)
                values.append(
                    row[at : at + size].reshape(aval.shape).astype(aval.dtype)
                )
                at += size
            gathered.append(jtu.tree_unflatten(treedef, values))
        return gathered


def _run_here(task):
    """A task `(key, program, leaves)` run in this process: its outputs, or the
    text of its failure (as `run_tasks` gives it)."""
    try:
        return _worker.run(*task)
    except Exception as error:  # noqa: BLE001  (reported as the experiment's failure)
        return f"{type(error).__name__}: {error}"


_RUNNING = {}  # token -> the `ExperimentPrograms` of a running identification


def register(evaluations) -> int:
    """A token (an int) under which `evaluate_registered` finds `evaluations`
    until `release`: host callbacks of a compiled iteration take arrays, not
    Python objects."""
    token = max(_RUNNING, default=0) + 1
    _RUNNING[token] = evaluations
    return token


def release(evaluations) -> None:
    """Forget `evaluations` (its identification has ended)."""
    for token in [k for k, v in _RUNNING.items() if v is evaluations]:
        del _RUNNING[token]


def evaluate_registered(token, x):
    """The registered evaluations `token` at `x` (a host callback)."""
    return _RUNNING[int(token)](x)


def _failed_like(aval):
    """The outputs of a failed chunk: NaN, or the failure code for integers."""
    if np.issubdtype(aval.dtype, np.floating):
        return np.full(aval.shape, np.nan, aval.dtype)
    return np.full(aval.shape, WORKER_FAILED, aval.dtype)


# --------------------------------------------------------------------------------------
# Group sizes from memory


def program_bytes(fn, args, device) -> int:
    """The memory XLA plans for `fn(*args)` on `device`: arguments, outputs and
    temporaries (less what outputs reuse of arguments), bytes."""
    flat, leaves, _, _ = _flat(fn, args)
    avals = [jax.ShapeDtypeStruct(x.shape, x.dtype) for x in leaves]
    compiled = jax.jit(flat, device=device).lower(*avals).compile()
    m = compiled.memory_analysis()
    return int(
        m.argument_size_in_bytes
        + m.output_size_in_bytes
        + m.temp_size_in_bytes
        - m.alias_size_in_bytes
    )


def fit_group(fn, args, n: int, device, free_bytes=None, budget=0.8, probe=(4, 8)):
    """The largest group of the `n` members `args[0]` (a tuple of `(n,)` value
    arrays) whose program `fn(group values, *args[1:])` fits `budget` of the free
    memory of `device` (`free_bytes`: the device's free memory, default from
    `device.memory_stats()`). The memory of a group grows linearly with its size:
    the slope and offset come from two small compiled probes. Without a memory
    limit (a CPU) all `n`."""
    if free_bytes is None:
        stats = device.memory_stats() or {}
        if not stats.get("bytes_limit"):
            return n
        free_bytes = stats["bytes_limit"] - stats.get("bytes_in_use", 0)
    vals = args[0]
    sizes = [min(p, n) for p in probe]
    if sizes[0] == sizes[1]:
        return n
    use = [
        program_bytes(fn, (tuple(v[:m] for v in vals),) + tuple(args[1:]), device)
        for m in sizes
    ]
    per = max((use[1] - use[0]) / (sizes[1] - sizes[0]), 1.0)
    base = use[0] - sizes[0] * per
    return int(max(1, min(n, (budget * free_bytes - base) // per)))


# --------------------------------------------------------------------------------------
# jax.distributed


def distributed() -> bool:
    """Whether this process is one of several of a `jax.distributed` job."""
    return jax.process_count() > 1


def process_block(n: int, group: int) -> tuple[int, int]:
    """(start, size) of this process's block of `n` members in a jax.distributed
    job: blocks of equal size, whole groups of `group` members (the last block may
    be shorter, or empty)."""
    size = math.ceil(n / (jax.process_count() * group)) * group
    start = min(n, jax.process_index() * size)
    return start, size


def gather_blocks(tree, n: int, size: int):
    """Every process's block of results (leaves `(b, ...)` with b <= `size`),
    gathered on every process into leaves `(n, ...)` in member order."""
    from jax.experimental import multihost_utils

    def pad(x):
        x = np.asarray(x)
        fill = np.zeros((size - x.shape[0],) + x.shape[1:], x.dtype)
        return np.concatenate([x, fill])

    gathered = multihost_utils.process_allgather(jtu.tree_map(pad, tree))
    return jtu.tree_map(
        lambda x: np.asarray(x).reshape((-1,) + np.shape(x)[2:])[:n], gathered
    )
