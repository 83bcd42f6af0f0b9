"""The one process-wide setting jaxstring makes on import, and the compilation cache.

* float64 everywhere (``jax_enable_x64``): stiff strings (EA up to 1e9) lose all
  accuracy in float32. This is the only setting `import jaxstring` changes.
* OpenBLAS threads are limited inside jaxstring's own calls only
  (`jaxstring._blas`); XLA:CPU's YNNPACK fusions are turned off per compilation
  for the solves (``jaxstring._jit``).
* The ``jaxstring`` command (and only it) runs with equinox's ``EQX_ON_ERROR=nan``
  unless the variable is set: equinox's runtime checks (in diffrax, lineax and
  optimistix) otherwise compile to host callbacks, and JAX does not write a
  program with host callbacks to its persistent compilation cache. A failed check
  then yields NaN data, which the solve's status reports. `enable_compilation_cache`
  tells API users the same.
"""

import os
import sys


if os.path.basename(sys.argv[0]) == "jaxstring":  # the console command
    os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)


def default_cache_dir() -> str:
    """``$JAXSTRING_CACHE_DIR``, else ``$XDG_CACHE_HOME/jaxstring/jax`` (default
    ``~/.cache/jaxstring/jax``)."""
    if os.environ.get("JAXSTRING_CACHE_DIR"):
        return os.environ["JAXSTRING_CACHE_DIR"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(
        os.path.expanduser("~"), ".cache"
    )
    return os.path.join(base, "jaxstring", "jax")


def enable_compilation_cache(
    path: str | None = None,
    min_compile_s: float = 0.5,
    warn: bool = True,
    programs: bool = False,
):
    """Turn on JAX's persistent compilation cache: compiled programs that took at
    least `min_compile_s` to compile are written to `path` (default
    `default_cache_dir()`) and read back by later processes, so a second run of
    the same scene skips its compilation. Returns the folder.

    JAX does not cache a program that contains host callbacks, and equinox's
    runtime checks compile to host callbacks unless ``EQX_ON_ERROR=nan`` (or
    ``off``) is set in the environment before equinox is imported: set it before
    importing jaxstring (the ``jaxstring`` command does), or the solves are not
    cached (a `UserWarning` says so unless `warn=False`).

    `programs=True` also saves `simulate`'s traced solves (in `path`/programs), so
    a later process skips tracing too (what that saves: docs/performance.md,
    "Compile time"). Loaded programs serve forward solves only (`fit` and `sweep`
    trace as before); see `jaxstring._programs` for what keys a saved program.
    """
    import warnings

    path = path or default_cache_dir()
    if not (isinstance(min_compile_s, (int, float)) and min_compile_s >= 0):
        raise ValueError(
            f"`min_compile_s` must be a number >= 0 s; got {min_compile_s!r}."
        )
    os.makedirs(path, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_s)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    from . import _programs

    _programs.set_program_folder(os.path.join(path, "programs") if programs else None)
    if warn and os.environ.get("EQX_ON_ERROR") not in ("nan", "off"):
        warnings.warn(
            "jaxstring's solves are not written to the compilation cache unless "
            "EQX_ON_ERROR=nan is set before importing jaxstring (equinox's runtime "
            "checks compile to host callbacks, which JAX does not cache).",
            stacklevel=2,
        )
    return path
