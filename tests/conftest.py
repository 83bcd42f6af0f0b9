import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

import jaxstring  # noqa: E402, F401  (float64 on)


# Persistent compilation cache, opt-in: JAXSTRING_TEST_CACHE=<dir> lets repeated
# local test runs skip most XLA compilation. It is off by default (jaxstring's own
# default cache in the user's home too) because a fresh CI run gains little from
# it and, once, segfaulted inside JAX while writing an executable to the cache
# (jax 0.10.2, compilation_cache.put_executable_and_time).
_cache = os.environ.get("JAXSTRING_TEST_CACHE")
os.environ.setdefault("JAXSTRING_CACHE", "on" if _cache else "off")
if _cache:
    jax.config.update("jax_compilation_cache_dir", os.path.abspath(_cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
