"""jaxstring's process settings: float64 on import, and OpenBLAS limited to one
thread inside jaxstring's own calls only.

On small machines a multi-threaded OpenBLAS can make the solvers' small LU
factorisations much slower (experiments/blas_threads.py measures it). The limit
must not leak into the user's own NumPy code. Each case runs in a fresh process,
because OpenBLAS reads its thread count when it loads.
"""

import json
import os
import subprocess
import sys

import pytest


pytest.importorskip("threadpoolctl")

_PROBE = r"""
import json, os, sys
order = sys.argv[1]
if order == "jaxstring_first":
    import jaxstring as js
import numpy as np
if order == "numpy_first":
    import jaxstring as js
import scipy.linalg  # the OpenBLAS that XLA:CPU's LAPACK calls
import jax.numpy as jnp
from threadpoolctl import threadpool_info

def blas():
    pools = threadpool_info()
    return sorted(i["num_threads"] for i in pools if i["user_api"] == "blas")

before = blas()
from jaxstring import _blas
with _blas.one_blas_thread():
    seen = blas()
scene = js.pendulum.string_pendulum(k=3, t1=0.05)
traj = js.simulate(scene, n_save=3)
after = blas()
print(json.dumps({"before": before, "inside": seen, "after": after,
                  "ok": bool(traj.ok), "dtype": str(jnp.asarray(1.0).dtype),
                  "xla_flags": os.environ.get("XLA_FLAGS")}))
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
        timeout=300,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "order", ["numpy_first", pytest.param("jaxstring_first", marks=pytest.mark.slow)]
)
def test_user_blas_threads_unchanged_outside_jaxstring_calls(order):
    cores = os.cpu_count()
    r = _probe(order)
    assert r["dtype"] == "float64"
    assert r["ok"]
    # The user's pools keep their own size before and after a jaxstring call.
    assert r["before"] and max(r["before"]) == cores
    assert r["after"] and max(r["after"]) == cores
    # Inside jaxstring's calls every BLAS pool runs one thread.
    assert r["inside"] and max(r["inside"]) == 1
    # XLA's flags are the user's: the whole-loop threshold is for jaxstring's own
    # processes (the command, its worker pools) only.
    assert r["xla_flags"] == os.environ.get("XLA_FLAGS")


def test_whole_loop_threshold_leaves_the_users_backend_options():
    from jaxstring._config import WHOLE_LOOP_BYTES, whole_loop_flags

    mine = "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=0"
    assert whole_loop_flags(mine) == mine
    raised = whole_loop_flags("--xla_cpu_enable_fast_math=false")
    assert raised.split() == [
        "--xla_cpu_enable_fast_math=false",
        "--xla_backend_extra_options="
        f"xla_cpu_small_while_loop_byte_threshold={WHOLE_LOOP_BYTES}",
    ]


def test_user_setting_is_respected():
    r = _probe("jaxstring_first", env_value="2")
    assert max(r["before"]) == 2 and max(r["after"]) == 2
    assert max(r["inside"]) == 2


def test_solves_run_under_the_limit(monkeypatch):
    # Every public solve enters the limit once per call.
    import threadpoolctl

    import jaxstring as js

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    calls = []
    real = threadpoolctl.ThreadpoolController.limit

    def spy(self, *args, **kwargs):
        calls.append(kwargs.get("limits"))
        return real(self, *args, **kwargs)

    monkeypatch.setattr(threadpoolctl.ThreadpoolController, "limit", spy)
    scene = js.pendulum.string_pendulum(k=3, t1=0.05)
    js.simulate(scene, n_save=3)
    assert calls == [1]


_RETRACE_PROBE = """
import json
import jax, jax.numpy as jnp
import jaxstring as js
traces = []
@jax.jit
def users(x):
    traces.append(1)
    return 2.0 * x
users(jnp.ones(3))
scene = js.pendulum.string_pendulum(k=3, t1=0.05)
js.simulate(scene, n_save=3)  # jaxstring's first solve imports its solvers
users(jnp.ones(3))
print(json.dumps(len(traces)))
"""


def test_first_solve_does_not_retrace_earlier_compiled_functions():
    # Every jit cache context created in a process is part of every jit cache key;
    # jaxstring creates its own on import, so that its first solve leaves the
    # functions jitted after `import jaxstring` (the user's, a deck's static
    # solve) compiled: called again, they are not traced again.
    env = dict(os.environ, JAXSTRING_CACHE="off")
    out = subprocess.run(
        [sys.executable, "-c", _RETRACE_PROBE],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == 1


def test_a_function_written_anew_at_each_call_reuses_the_compiled_call():
    # A lambda in a call (a sweep's summary, a fit's loss) is a new function object
    # each time. jaxstring's compiled calls key it by its code and the objects it
    # captures: the same lambda again reuses the program, one capturing another
    # object compiles its own (and computes with it).
    import jax.numpy as jnp

    from jaxstring._jit import cpu_jit

    apply = cpu_jit(lambda x, f: f(x))

    def call(scale):
        return apply(jnp.arange(3.0), lambda x: scale * x)

    two = 2.0
    first, again = call(two), call(two)
    assert apply.cache_size() == 1
    assert jnp.array_equal(first, again) and float(first[2]) == 4.0
    assert float(call(3.0)[2]) == 6.0 and apply.cache_size() == 2
    # other code, same captures: its own program
    assert float(apply(jnp.arange(3.0), lambda x: x + two)[2]) == 4.0
    assert apply.cache_size() == 3


def test_a_long_compiled_call_says_so_once_and_a_short_one_stays_quiet(
    monkeypatch, capsys
):
    # One line on stderr for a block that outlasts the notice time (a compiling
    # first call), none for blocks that end in time, however many run.
    import time

    from jaxstring import _jit

    monkeypatch.setattr(_jit, "NOTICE_AFTER_S", 0.2)
    for _ in range(200):
        with _jit.compile_notice("quick"):
            pass
    start = time.monotonic()
    with _jit.compile_notice("slow one"):
        err = ""
        while "slow one" not in err and time.monotonic() < start + 10.0:
            time.sleep(0.02)
            err += capsys.readouterr().err
        said = time.monotonic() - start
    time.sleep(0.5)
    err += capsys.readouterr().err
    assert err.count("jaxstring: compiling slow one for this structure") == 1
    assert "quick" not in err
    assert 0.2 <= said < 1.0  # when the time was up, not at the watcher's pace
