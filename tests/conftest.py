import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

import jaxstring  # noqa: E402, F401  (float64 on)


# Persistent compilation cache: repeated test runs skip most XLA compilation.
_cache = os.environ.get(
    "JAXSTRING_TEST_CACHE",
    os.path.join(os.path.dirname(__file__), "..", ".jax_cache"),
)
jax.config.update("jax_compilation_cache_dir", os.path.abspath(_cache))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
