"""OpenBLAS threads inside jaxstring's calls, and nowhere else.

XLA:CPU's LAPACK kernels (the LU factorisations of the implicit solvers' Newton
matrices) call the OpenBLAS bundled with SciPy. On small machines a multi-threaded
OpenBLAS can make these small factorisations far slower than one thread does
(docs/numerics.md, "BLAS and XLA notes"), so jaxstring's solves run with one
OpenBLAS thread. The limit holds only while a jaxstring call runs
(`threadpoolctl`); the user's own NumPy and SciPy code keeps its thread count. A
user who sets ``OPENBLAS_NUM_THREADS`` keeps that value everywhere.
"""

import contextlib
import functools
import os

import jax

from ._config import ensure_compilation_cache


@contextlib.contextmanager
def one_blas_thread():
    """Limit every loaded BLAS library to one thread while the block runs."""
    if "OPENBLAS_NUM_THREADS" in os.environ:
        yield
        return
    with _controller().limit(limits=1, user_api="blas"):
        yield


@functools.cache
def _controller():
    """threadpoolctl's view of the loaded BLAS libraries, found once: a fresh
    `threadpool_limits` looks for them again on every call, which costs more
    than a small solve's run (docs/performance.md, "Compile time"). The
    OpenBLAS that XLA:CPU's LAPACK calls loads with SciPy's LAPACK, imported
    first (at the first factorisation otherwise, after the limit would have been
    applied)."""
    import scipy.linalg.cython_lapack  # noqa: F401
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def single_blas_thread(fn):
    """`fn` run under `one_blas_thread`, its JAX outputs computed before the limit
    is lifted (JAX dispatches asynchronously); the compilation cache decided first
    (`jaxstring._config.ensure_compilation_cache`)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        ensure_compilation_cache()
        with one_blas_thread():
            return jax.block_until_ready(fn(*args, **kwargs))

    return wrapper
