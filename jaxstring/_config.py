"""Process-wide settings jaxstring needs before JAX starts.

* float64 everywhere: stiff strings (EA up to 1e9) lose all accuracy in float32.
* OpenBLAS threading: on small (2-core) machines a multi-threaded OpenBLAS makes a
  160 x 160 LU factorisation hundreds of times slower (JAX's CPU LAPACK calls go to
  the OpenBLAS bundled with SciPy). We default ``OPENBLAS_NUM_THREADS`` to 1 before
  NumPy/SciPy load it, and, where OpenBLAS was already loaded by the user's own
  imports and ``threadpoolctl`` is installed, limit it at run time too. A user who
  wants something else sets the variable before importing jaxstring.
* XLA:CPU's YNNPACK fusions are turned off per compilation for `simulate`, `fit`
  and `sweep` (``jaxstring._jit``), not process-wide.
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


jax.config.update("jax_enable_x64", True)
