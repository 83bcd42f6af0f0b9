"""The worker side of jaxstring's process pools: run a saved program on a chunk.

A worker is a process of a `concurrent.futures` executor (jaxstring's own spawn
pool over the host's cores, or one the user passes). The parent traces a sweep's
chunk program, or an identification's experiment program, once and saves it
(`jax.export`, pickled as `jaxstring._programs` stores programs); a worker loads
it, compiles it on its CPU (or loads the executable a worker on this machine
saved, `jaxstring._executables`, or finds the compilation in the persistent
cache), and runs it on the arrays it is sent. Only JAX is needed here: a worker traces
nothing.

Compiling once for the pool. Every worker of a pool gets the same program at the
same moment. With a compilation cache, the first worker to take a program
compiles it and writes it to the cache while the others wait for it
(`_compile`, a file lock next to the cache) and then read it from the cache:
one compilation instead of one per worker. A worker bound to a core
(`_distribute.pinned_cores`) lets its threads use all the pool's cores while it
compiles (XLA:CPU compiles on several threads; bound to one core, the same
compilation took about 1.5 times as long) and binds them to its core again to run.
"""

import contextlib
import os
import pickle
import time


_COMPILED = {}  # program key -> compiled call, per worker process
_BOUND = {}  # this worker's core and the pool's cores, when it is bound to a core


def init(cache_dir: str | None, cores=None, started=None) -> None:
    """Set up a worker of jaxstring's own pool: float64, the CPU backend (a GPU
    stays with the parent), the shared compilation cache, one OpenBLAS thread,
    whole-loop kernels (`jaxstring._config.whole_loop_flags`).
    With `cores` (a list) the n-th worker started (`started`, a shared counter)
    runs on core `cores[n % len(cores)]` alone (but for its compilations:
    `_compile`)."""
    from ._config import whole_loop_flags

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    # before this process compiles anything: XLA reads its flags once
    os.environ["XLA_FLAGS"] = whole_loop_flags(os.environ.get("XLA_FLAGS"))
    if cores and started is not None and hasattr(os, "sched_setaffinity"):
        with started.get_lock():
            n = started.value
            started.value += 1
        _BOUND["core"], _BOUND["cores"] = cores[n % len(cores)], set(cores)
        os.sched_setaffinity(0, {_BOUND["core"]})
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_platforms", "cpu")
    if cache_dir:
        jax.config.update("jax_compilation_cache_dir", cache_dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    if _BOUND:
        from ._jit import cpu_compiler_options

        # XLA sizes its threads to the cores a thread sees when it starts them:
        # its client's (which run the programs) to this worker's one core, its
        # compiler's (started at the first compilation) to all the pool's.
        jax.devices("cpu")
        with _all_cores():
            cpu_compiler_options()


def _bind(cores) -> None:
    """Bind every thread of this process (Python's and XLA's) to `cores`."""
    for tid in os.listdir("/proc/self/task"):
        try:
            os.sched_setaffinity(int(tid), cores)
        except OSError:  # a thread that has ended meanwhile
            pass


@contextlib.contextmanager
def _all_cores():
    """A bound worker's threads on all the pool's cores for the block."""
    if not _BOUND:
        yield
        return
    _bind(_BOUND["cores"])
    try:
        yield
    finally:
        _bind({_BOUND["core"]})


def _compile(lowered, key: str, cache_dir: str | None):
    """`lowered` (program `key`) compiled once for the pool: the first worker
    compiles it, on all the pool's cores, and writes it to the compilation cache
    `cache_dir`; the others wait for it (a file lock) and read it from the cache,
    each on its own core. Once a program is marked compiled (a file next to the
    lock), nobody waits. Without a cache, or without POSIX file locks, each worker
    compiles it."""
    try:
        import fcntl
    except ImportError:
        fcntl = None
    if not cache_dir or fcntl is None:
        with _all_cores():
            return lowered.compile()
    folder = os.path.join(cache_dir, "jaxstring-compiling")
    done = os.path.join(folder, key + ".done")
    if os.path.exists(done):
        return lowered.compile()
    os.makedirs(folder, exist_ok=True)
    with open(os.path.join(folder, key + ".lock"), "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            if os.path.exists(done):
                return lowered.compile()
            with _all_cores():
                compiled = lowered.compile()
            with open(done, "w"):
                pass
            return compiled
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def ready() -> tuple:
    """This worker's process id and the cores it may run on: submitted once to
    start a pool's processes."""
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    return os.getpid(), cores


def pool_flags() -> str:
    """The XLA flags of a worker that this process starts (`init`)."""
    from ._config import whole_loop_flags

    return whole_loop_flags(os.environ.get("XLA_FLAGS"))


def folder() -> str | None:
    """Where workers save the executables of their programs: the compilation
    cache's `programs` folder (None: no cache)."""
    import jax

    cache_dir = jax.config.jax_compilation_cache_dir
    return os.path.join(cache_dir, "programs") if cache_dir else None


def run(key: str, program: bytes, leaves: list):
    """The pickled exported `program` (named `key`) applied to `leaves` (NumPy
    arrays); its outputs as NumPy arrays. With a compilation cache, the program's
    executable is read from its `programs` folder where a worker on this machine
    saved it, else compiled (`_compile`) and saved there (`jaxstring._executables`)."""
    return run_timed(key, program, leaves)[0]


def run_timed(key: str, program: bytes, leaves: list):
    """`run`'s outputs, and the seconds the compiled program ran for them (its
    compilation or loading apart)."""
    import jax

    from . import _executables as executables
    from ._jit import cpu_compiler_options

    jax.config.update("jax_enable_x64", True)
    compiled = _COMPILED.get(key)
    if compiled is None:
        cache_dir = jax.config.jax_compilation_cache_dir
        saved = folder()
        if saved is not None:
            compiled = executables.read(saved, key, "full")
        if compiled is None:
            exported = pickle.loads(program)
            lowered = jax.jit(
                executables.named_call(exported, key, "full"),
                compiler_options=cpu_compiler_options(),
            ).lower(*leaves)
            if saved is not None:
                os.makedirs(saved, exist_ok=True)
            compiled = executables.compile_and_save(
                lowered,
                saved,
                key,
                "full",
                executables.uses_lapack(exported),
                compiler=lambda lowered: _compile(lowered, key, cache_dir),
            )
        _COMPILED[key] = compiled
    start = time.perf_counter()
    out = jax.device_get(compiled(*leaves))
    return out, time.perf_counter() - start
