"""Process-wide settings jaxstring needs before JAX starts.

* float64 everywhere: stiff strings (EA up to 1e9) lose all accuracy in float32.
* OpenBLAS threading: on small (2-core) machines a multi-threaded OpenBLAS makes a
  160 x 160 LU factorisation hundreds of times slower (JAX's CPU LAPACK calls go to
  the OpenBLAS bundled with SciPy). We default ``OPENBLAS_NUM_THREADS`` to 1 before
  NumPy/SciPy load it, and, where OpenBLAS was already loaded by the user's own
  imports and ``threadpoolctl`` is installed, limit it at run time too. A user who
  wants something else sets the variable before importing jaxstring.
* XLA:CPU's YNNPACK library fusions: jaxlib 0.10 hands batched reductions (the
  colour-batched Jacobian-vector products of a string's banded Jacobian) to
  YNNPACK, which made them 3-4x slower than XLA's own loops at 640-1280 elements on
  the 2-core machines (experiments/results/ynn_fusion.md). We add
  ``--xla_cpu_experimental_ynn_fusion_type=`` (no YNNPACK fusions) to
  ``XLA_FLAGS`` if the user has not set that flag, the jaxlib is one where it was
  measured (0.10), and JAX has not started its CPU backend yet (XLA reads the
  variable then). ``XLA_FLAGS_SET_BY`` says what happened.
"""

import os
import sys


def _limit_blas_threads() -> str:
    """Keep OpenBLAS single-threaded; return how it was done (for diagnostics)."""
    already = "OPENBLAS_NUM_THREADS" in os.environ
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    if already:
        return "user setting OPENBLAS_NUM_THREADS=" + os.environ["OPENBLAS_NUM_THREADS"]
    if "numpy" in sys.modules or "scipy" in sys.modules:
        # OpenBLAS may already have started its threads; the variable is read at
        # load time only, so limit the live pools when threadpoolctl is present.
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            return "environment (may be late: numpy was imported first)"
        threadpool_limits(limits=1, user_api="blas")
        return "threadpoolctl"
    return "environment"


BLAS_THREADS_SET_BY = _limit_blas_threads()

import jax  # noqa: E402


_YNN_FLAG = "--xla_cpu_experimental_ynn_fusion_type="


def _no_ynn_fusions() -> str:
    """Turn XLA:CPU's YNNPACK fusions off where safe; return what was done."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_experimental_ynn_fusion_type" in flags:
        return "user setting in XLA_FLAGS"
    try:
        import jaxlib

        version = tuple(int(x) for x in jaxlib.__version__.split(".")[:2])
    except (ImportError, ValueError):
        return "not set (jaxlib version unknown)"
    if version != (0, 10):
        # An unknown flag aborts XLA: only set it where it is known to exist.
        return f"not set (jaxlib {jaxlib.__version__} not measured)"
    from jax._src import xla_bridge

    started = getattr(xla_bridge, "backends_are_initialized", lambda: False)()
    if started:
        return "not set (the JAX backend had already started)"
    os.environ["XLA_FLAGS"] = (flags + " " + _YNN_FLAG).strip()
    return "XLA_FLAGS"


XLA_FLAGS_SET_BY = _no_ynn_fusions()


jax.config.update("jax_enable_x64", True)
