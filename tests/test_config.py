"""jaxstring's process settings: float64, and the OpenBLAS thread guard.

On 2-core machines a multi-threaded OpenBLAS can make small LU factorisations
hundreds of times slower (experiments/blas_threads.py measures it). jaxstring limits
OpenBLAS to one thread unless the user chose a value. Each case runs in a fresh
process, because OpenBLAS reads its thread count when it loads.
"""

import json
import os
import subprocess
import sys

import pytest


_PROBE = r"""
import json, os, sys
order = sys.argv[1]
if order == "jaxstring_first":
    import jaxstring
import numpy as np
if order == "numpy_first":
    import jaxstring
import jax.numpy as jnp
try:
    from threadpoolctl import threadpool_info
    live = [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
except ImportError:
    live = None
from jaxstring import _config
print(json.dumps({"env": os.environ.get("OPENBLAS_NUM_THREADS"), "live": live,
                  "how": _config.BLAS_THREADS_SET_BY,
                  "dtype": str(jnp.asarray(1.0).dtype)}))
"""


def _probe(order, env_value=None):
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if env_value is not None:
        env["OPENBLAS_NUM_THREADS"] = env_value
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, order],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_jaxstring_first_sets_one_thread_and_float64():
    r = _probe("jaxstring_first")
    assert r["env"] == "1"
    assert r["how"] == "environment"
    assert r["dtype"] == "float64"
    if r["live"] is not None:
        assert r["live"] and max(r["live"]) == 1


def test_numpy_first_is_limited_at_run_time():
    pytest.importorskip("threadpoolctl")
    r = _probe("numpy_first")
    assert r["how"] == "threadpoolctl"
    assert r["live"] and max(r["live"]) == 1


def test_user_setting_is_respected():
    r = _probe("jaxstring_first", env_value="2")
    assert r["env"] == "2"
    assert r["how"].startswith("user setting")
