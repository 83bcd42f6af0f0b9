"""Compiled executables saved to a folder and loaded by later processes.

XLA's executable of a program (`jax.stages.Compiled`), serialised with
`jax.experimental.serialize_executable`, is machine code for this machine's
processor: it is saved under the program's key and a key of the machine
(`machine`) and only loaded where both match. A process that loads one skips
the program's tracing, lowering and compilation (`jaxstring._programs`: saved
programs; `jaxstring._worker`: the chunk programs of a process pool). Only JAX
is imported here (a pool's workers import nothing else).

Two things an executable needs that its lowering would have done, and which
loading it skips or loses:

- jaxlib's LAPACK kernels (LU, triangular solves) find their routines (in scipy)
  when JAX first lowers one of them; an executable that calls LAPACK is saved
  with a flag, and they are made ready before it is loaded (without it its first
  LAPACK call jumps to a null routine);
- XLA:CPU serialises an executable that JAX read from its compilation cache
  incompletely (a later process that loads it fails to find its kernels), so
  only an executable compiled in the process is saved (`compile_and_save`). A
  saved program is compiled under a name of its own key (`named_call`): the name
  is part of its key in JAX's cache, so a renamed program (a new jaxstring
  source, the same operations) is compiled, not read from there.

An executable is machine code: like the rest of the cache folder, read only what
this user's own processes wrote.
"""

import contextlib
import functools
import hashlib
import importlib
import os
import pathlib
import pickle
import platform
import threading

import jax
import numpy as np
from jax.experimental import serialize_executable


def named_call(exported, key: str, tier: str):
    """`exported.call` (a `jax.export.Exported`) named after the program's key and
    tier ("full" or "quick"): the name of its compiled module."""

    def call(*leaves):
        return exported.call(*leaves)

    call.__name__ = call.__qualname__ = f"saved_{key[:16]}_{tier}"
    return call


# The JAX versions whose private export steps `export_with_lowering` repeats.
EXPORT_TESTED = ((0, 10, 2), (0, 11, 0))  # >= 0.10.2, < 0.11


def export_with_lowering(jitted, avals):
    """(`jax.export.export(jitted, platforms=("cpu",))(*avals)`, the
    `jax.stages.Lowered` that export made it from, or None).

    A process that traced a program compiles the export's own lowering: calling
    the exported program would lower it again, around a copy of its module
    (serialised and read back), and JAX's lowering of such a call makes LAPACK's
    kernels ready whether or not the program calls them (importing
    `scipy.linalg`; measured: docs/performance.md, "A warm process runs the saved
    executable"). `jax.export` keeps its lowering to itself, so this repeats its
    steps (trace; lower for export; JAX's private `_export_lowered`) for the JAX
    versions in `EXPORT_TESTED`; for another version, or where that API has
    moved, it exports through the public function and returns no lowering."""
    version = tuple(int(p) for p in jax.__version__.split(".")[:3] if p.isdigit())
    if EXPORT_TESTED[0] <= version < EXPORT_TESTED[1]:
        try:
            from jax._src import config
            from jax._src.export import _export
            from jax._src.interpreters import mlir

            traced = jitted.trace(*avals)
            parameters = mlir.LoweringParameters(
                for_export=True,
                hoist_constants_as_args=False,
                export_ignore_forward_compatibility=(
                    config.export_ignore_forward_compatibility.value
                ),
            )
            lowered = traced.lower(
                lowering_platforms=("cpu",), _private_parameters=parameters
            )
            exported = _export._export_lowered(lowered, traced.jaxpr, traced.fun_name)
            return exported, lowered
        except (ImportError, AttributeError, TypeError):  # moved: the public way
            pass
    return jax.export.export(jitted, platforms=("cpu",))(*avals), None


def uses_lapack(exported) -> bool:
    """Whether the traced program calls jaxlib's LAPACK kernels."""
    return b"lapack_" in exported.mlir_module_serialized


@functools.cache
def machine(flags: str | None = None) -> str:
    """What an executable compiled here is keyed by besides its program: XLA's
    CPU client (its version), the CPU devices, the XLA flags (`flags`; None:
    this process's), the processor (its model and instruction-set flags: XLA:CPU
    compiles for the host's)."""
    cpu = jax.devices("cpu")
    h = hashlib.sha256()
    for part in (
        cpu[0].client.platform_version,
        str(len(cpu)),
        os.environ.get("XLA_FLAGS", "") if flags is None else flags,
        platform.machine(),
        platform.processor(),
        _processor(),
    ):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:16]


def _processor() -> str:
    """The first processor's vendor, model and flags (Linux's /proc/cpuinfo;
    empty elsewhere)."""
    try:
        text = pathlib.Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""
    first = text.split("\n\n")[0].splitlines()
    wanted = ("vendor_id", "model name", "flags", "Features", "CPU part")
    return "\n".join(line for line in first if line.startswith(wanted))


def path(folder, key: str, tier: str, flags: str | None = None) -> pathlib.Path:
    """Where the executable of program `key` compiled on this machine is saved
    (by a process with the XLA flags `flags`; None: this process's)."""
    return pathlib.Path(folder) / f"{key}.{machine(flags)}.{tier}.executable"


def read(folder, key: str, tier: str, flags: str | None = None):
    """The executable of `key` saved by a process on this machine (with the XLA
    flags `flags`; None: this process's), loaded for the first CPU device; None
    where there is none or it cannot be loaded (then it is compiled again)."""
    try:
        payload, in_tree, out_tree, lapack = pickle.loads(
            path(folder, key, tier, flags).read_bytes()
        )
        if lapack:
            _lapack_ready()
        return serialize_executable.deserialize_and_load(
            payload,
            in_tree,
            out_tree,
            backend="cpu",
            execution_devices=jax.devices("cpu")[:1],
        )
    except Exception:  # noqa: BLE001  (none, unreadable, another version's)
        return None


@functools.cache
def _lapack_ready() -> None:
    from jaxlib import lapack

    lapack.prepare_lapack_call("getrf_ffi", np.dtype(np.float64))


_WHILE_COMPILING: list = []  # modules for the next compilation to import meanwhile


@contextlib.contextmanager
def imports_while_compiling(*modules: str):
    """Within the block, the first compilation of `compile_and_save` imports
    `modules` in a thread while XLA compiles (in C++, with Python's interpreter
    lock released): for a caller that needs them once the solve is done (the
    command's figure). Where nothing is compiled (a saved executable) they are
    imported where they are used, as before."""
    _WHILE_COMPILING[:] = modules
    try:
        yield
    finally:
        _WHILE_COMPILING.clear()


def _import(modules) -> None:
    for name in modules:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001  (raised again where it is imported)
            pass


def compile_and_save(
    lowered, folder, key: str, tier: str, lapack: bool, compiler=None, jax_cache=True
):
    """`lowered` compiled (by `compiler(lowered)`, default `lowered.compile()`) and,
    where that compiled it rather than reading it from JAX's compilation cache,
    saved in `folder` (None: not saved) with the flag `lapack` (`uses_lapack`).
    `jax_cache`: False where no other process reads the compilation from JAX's
    cache (`_no_cache_write`)."""
    if _WHILE_COMPILING:
        modules = tuple(_WHILE_COMPILING)
        _WHILE_COMPILING.clear()
        threading.Thread(target=_import, args=(modules,), name="imports").start()
    hits = _cache_hits()
    with contextlib.nullcontext() if jax_cache else _no_cache_write():
        compiled = lowered.compile() if compiler is None else compiler(lowered)
    if folder is not None and _cache_hits() == hits:
        _write(path(folder, key, tier), compiled, lapack)
    return compiled


@contextlib.contextmanager
def _no_cache_write():
    """Within the block (in this thread), JAX writes no compilation to its
    persistent cache. A saved program's executable is saved by jaxstring (and
    is the one a later process loads): JAX's own copy of it, serialised and
    written a second time (docs/performance.md), would only be read by a
    process that traces the same program again, whose executable then could
    not be saved (an executable read from that cache serialises incompletely).
    JAX's threshold of compilation time for a write is a thread-local setting
    (private: for another JAX, where it has moved, the block writes as before)."""
    try:
        from jax._src import config

        threshold = config.persistent_cache_min_compile_time_secs(float("inf"))
    except (ImportError, AttributeError, TypeError):  # moved: written as before
        threshold = contextlib.nullcontext()
    with threshold:
        yield


def _write(target: pathlib.Path, compiled, lapack: bool) -> None:
    try:
        data = pickle.dumps((*serialize_executable.serialize(compiled), lapack))
        tmp = target.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_bytes(data)
        os.replace(tmp, target)
    except Exception:  # noqa: BLE001  (not saved: the next process compiles it)
        pass


_HITS = threading.local()


def _count_hit(event: str, **kwargs) -> None:
    if event == "/jax/compilation_cache/cache_hits":
        _HITS.count = getattr(_HITS, "count", 0) + 1


@functools.cache
def _listening() -> None:
    jax.monitoring.register_event_listener(_count_hit)


def _cache_hits() -> int:
    """How many compilations this thread has read from JAX's compilation cache."""
    _listening()
    return getattr(_HITS, "count", 0)
