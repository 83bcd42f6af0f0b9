"""The one process-wide setting jaxstring makes on import, and the compilation cache.

* float64 everywhere (``jax_enable_x64``): stiff strings (EA up to 1e9) lose all
  accuracy in float32. This is the only setting `import jaxstring` changes (with
  one jit-cache context of its own, `NAN_CHECKS_CONTEXT`: like float64, it makes a
  function jitted before `import jaxstring` trace once more).
* OpenBLAS threads are limited inside jaxstring's own calls only
  (`jaxstring._blas`); XLA:CPU's YNNPACK fusions are turned off per compilation
  for the solves (``jaxstring._jit``).
* At jaxstring's first compiled call (not on import: the first solve, or a
  scene's build), JAX's persistent compilation cache
  is turned on in a per-user folder unless the user configured it or set
  ``JAXSTRING_CACHE=off`` (`enable_compilation_cache`), so that a second process
  solving a scene of the same structure skips tracing and compiling it.
* The ``jaxstring`` command (and only it) runs with equinox's ``EQX_ON_ERROR=nan``
  unless the variable is set: a failed runtime check of diffrax, lineax or
  optimistix then yields NaN data, which the solve's status reports.
* jaxstring's own processes (the ``jaxstring`` command and the worker processes
  of its sweep and identification pools), and only they, raise XLA:CPU's
  small-while-loop threshold (`whole_loop_flags`) unless ``XLA_FLAGS`` already
  sets XLA's backend options: a user's process keeps XLA's defaults.
"""

import os
import sys


WHOLE_LOOP_BYTES = 1 << 20
"""XLA:CPU compiles a while loop whose buffers take fewer bytes than this as one
kernel (``xla_cpu_small_while_loop_byte_threshold``; XLA's own default is 1 kB),
instead of dispatching its body's kernels one by one on every iteration. The
solve loop of a small adaptive solve (the default pendulum) then runs as one
kernel; loops with more state keep XLA's default treatment (a larger value made
other programs compile several times longer). Measured in docs/performance.md,
"Whole-loop kernels on the CPU"."""


def whole_loop_flags(flags: str | None) -> str:
    """The ``XLA_FLAGS`` value `flags` with XLA:CPU's small-while-loop threshold
    raised to `WHOLE_LOOP_BYTES`, or `flags` unchanged where it already sets
    XLA's backend options (the user's choice stands). Only takes effect in a
    process that has not started XLA yet; process-wide, so jaxstring applies it
    only to processes of its own."""
    flags = flags or ""
    if "xla_backend_extra_options" in flags:
        return flags
    option = f"xla_cpu_small_while_loop_byte_threshold={WHOLE_LOOP_BYTES}"
    return f"{flags} --xla_backend_extra_options={option}".strip()


if os.path.basename(sys.argv[0]) == "jaxstring":  # the console command
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    os.environ["XLA_FLAGS"] = whole_loop_flags(os.environ.get("XLA_FLAGS"))

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

# A jit-cache context of jaxstring's own (programs traced to be saved for worker
# processes: `jaxstring._solvers.diffrax_compat.checks_as_nan`). Creating a context
# adds an entry to every jit cache key in the process, so that every function
# jitted before it traces again once: it is created here, on import beside
# float64 (which does the same), not at the first solve, where it made the user's
# and jaxstring's own earlier compiled calls (a deck's static state) trace again.
# JAX does not create user contexts safely while other threads trace either.
NAN_CHECKS_CONTEXT = jax.make_user_context(default_value=False)


def default_cache_dir() -> str:
    """``$JAXSTRING_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxstring/jax`` (default
    ``~/.cache/jaxstring/jax``)."""
    if os.environ.get("JAXSTRING_CACHE_DIR"):
        return os.environ["JAXSTRING_CACHE_DIR"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(
        os.path.expanduser("~"), ".cache"
    )
    return os.path.join(base, "jaxstring", "jax")


_CACHE = {"state": None}  # None: not yet decided; else the folder or "off"
_PROGRAMS = {"path": None}  # where traced solves are saved (`jaxstring._programs`)


def set_program_folder(path: str | None) -> None:
    """Save and load traced solve programs in `path` (None: off)."""
    if path is not None:
        os.makedirs(path, exist_ok=True)
    _PROGRAMS["path"] = path


def program_folder() -> str | None:
    """The folder of saved solve programs (None: off)."""
    return _PROGRAMS["path"]


def enable_compilation_cache(
    path: str | None = None,
    min_compile_s: float = 0.05,
    programs: bool = True,
):
    """Turn on JAX's persistent compilation cache: compiled programs that took at
    least `min_compile_s` to compile are written to `path` (default
    `default_cache_dir()`) and read back by later processes, so a second process
    that solves a scene of the same structure skips its compilation. With
    `programs` (default), `simulate`'s traced solves are saved too (in
    `path`/programs), so that process skips tracing as well (see
    `jaxstring._programs`). Returns the folder.

    jaxstring does this itself at its first compiled call, unless JAX's cache was
    already configured (then it is left as it is) or ``JAXSTRING_CACHE=off`` is
    set; call it to choose another folder. `disable_compilation_cache` turns it
    off. JAX's cache is process-wide: from then on it also keeps the user's own
    programs that take `min_compile_s` or more to compile.
    """
    path = path or default_cache_dir()
    if not (isinstance(min_compile_s, (int, float)) and min_compile_s >= 0):
        raise ValueError(
            f"`min_compile_s` must be a number >= 0 s; got {min_compile_s!r}."
        )
    os.makedirs(path, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_s)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    set_program_folder(os.path.join(path, "programs") if programs else None)
    _CACHE["state"] = path
    return path


def disable_compilation_cache():
    """Stop jaxstring from saving and loading compiled and traced solves (JAX's
    compilation cache stays as the user configured it)."""
    set_program_folder(None)
    if _CACHE["state"] not in (None, "off"):
        jax.config.update("jax_compilation_cache_dir", None)
    _CACHE["state"] = "off"


def cache_off_by_environment() -> bool:
    """Whether ``JAXSTRING_CACHE`` asks for no compilation cache (off, 0, false, no)."""
    return os.environ.get("JAXSTRING_CACHE", "").lower() in ("off", "0", "false", "no")


def ensure_compilation_cache():
    """At jaxstring's first compiled call: the persistent compilation cache on in
    `default_cache_dir()`, unless ``JAXSTRING_CACHE=off``, the user configured
    JAX's cache, or `disable_compilation_cache` was called."""
    if _CACHE["state"] is not None:
        return
    if cache_off_by_environment():
        _CACHE["state"] = "off"
        return
    if jax.config.jax_compilation_cache_dir:  # the user's own setting
        _CACHE["state"] = jax.config.jax_compilation_cache_dir
        return
    try:
        enable_compilation_cache()
    except OSError:  # a read-only or missing home: solve without the cache
        _CACHE["state"] = "off"
