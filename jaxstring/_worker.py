"""The worker side of jaxstring's process pools: run a saved program on a chunk.

A worker is a process of a `concurrent.futures` executor (jaxstring's own spawn
pool over the host's cores, or one the user passes). The parent traces a sweep's
chunk program, or an identification's experiment program, once and saves it
(`jax.export`, pickled as `jaxstring._programs` stores programs); a worker loads
it, compiles it on its CPU (or finds the compilation in the persistent cache),
and runs it on the arrays it is sent. Only JAX is needed here: a worker traces
nothing.
"""

import os
import pickle


_COMPILED = {}  # program key -> compiled call, per worker process


def init(cache_dir: str | None, cores=None, started=None) -> None:
    """Set up a worker of jaxstring's own pool: float64, the CPU backend (a GPU
    stays with the parent), the shared compilation cache, one OpenBLAS thread,
    whole-loop kernels (`jaxstring._config.whole_loop_flags`).
    With `cores` (a list) the n-th worker started (`started`, a shared counter)
    runs on core `cores[n % len(cores)]` alone."""
    from ._config import whole_loop_flags

    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    # before this process compiles anything: XLA reads its flags once
    os.environ["XLA_FLAGS"] = whole_loop_flags(os.environ.get("XLA_FLAGS"))
    if cores and started is not None and hasattr(os, "sched_setaffinity"):
        with started.get_lock():
            n = started.value
            started.value += 1
        os.sched_setaffinity(0, {cores[n % len(cores)]})
    import jax

    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_platforms", "cpu")
    if cache_dir:
        jax.config.update("jax_compilation_cache_dir", cache_dir)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def ready() -> tuple:
    """This worker's process id and the cores it may run on: submitted once to
    start a pool's processes."""
    cores = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    return os.getpid(), cores


def run(key: str, program: bytes, leaves: list):
    """The pickled exported `program` (named `key`) applied to `leaves` (NumPy
    arrays); its outputs as NumPy arrays."""
    import jax

    from ._jit import cpu_compiler_options

    jax.config.update("jax_enable_x64", True)
    compiled = _COMPILED.get(key)
    if compiled is None:
        exported = pickle.loads(program)
        compiled = jax.jit(exported.call, compiler_options=cpu_compiler_options())
        _COMPILED[key] = compiled
    return jax.device_get(compiled(*leaves))
