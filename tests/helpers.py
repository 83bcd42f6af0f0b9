"""Shared helpers: cached simulations so that tests reuse compiled solves, a
process pool whose workers die on cue, and a fresh process with two CPU devices."""

import concurrent.futures as cf
import functools
import multiprocessing
import os
import signal
import socket
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js


FORMULATIONS = ("displacement", "natural", "angle")

# The natural and angle forms integrate the same ODE (test_physics checks it at
# k = 10): a check parametrized over formulations runs the angle form among the
# slow tests.
FORMULATIONS_FAST = (
    "displacement",
    "natural",
    pytest.param("angle", marks=pytest.mark.slow),
)


@functools.cache
def run(
    formulation,
    k=10,
    EA=1e4,
    alpha=0.01,
    t1=1.0,
    solver="kvaerno5",
    rtol=1e-8,
    atol=1e-8,
    n_save=101,
    max_steps=200_000,
    **scene_options,
):
    """Simulate a string pendulum, saved at `n_save` points over [0, t1];
    `scene_options`: further arguments of `string_pendulum` (`theta0`, `mu`, `m_s`,
    `l`, `g`, `dim`, `effects`, ...). Cached on all arguments."""
    scene = js.string_pendulum(
        formulation=formulation, k=k, EA=EA, alpha=alpha, t1=t1, **scene_options
    )
    ts = jnp.linspace(0.0, t1, n_save)
    return js.simulate(scene, solver, rtol=rtol, atol=atol, ts=ts, max_steps=max_steps)


def zero_crossings(t, x):
    """Times where x changes sign (linear interpolation)."""
    t = np.asarray(t)
    x = np.asarray(x)
    i = np.nonzero(np.sign(x[:-1]) * np.sign(x[1:]) < 0)[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


def fitted_order(hs, errors):
    """Slope of log(error) against log(h) by least squares."""
    return float(np.polyfit(np.log(hs), np.log(errors), 1)[0])


# The string pendulum's alpha and EA, as `_fit` getters.
ALPHA_EA = (
    ("alpha", lambda s: s.effects[1].alpha),
    ("EA", lambda s: s.model.EA),
)


def assert_grad_matches_central_differences(
    loss_fn, scene, grad, getters=ALPHA_EA, rel_step=1e-4, rtol=1e-5
):
    """Each `grad[name]` against the central difference of `loss_fn(scene)` in the
    parameter `get(scene)`, with step `rel_step` times the parameter (truncation
    ~ rel_step^2, rounding ~ solver tolerance / rel_step)."""
    import equinox as eqx

    loss = eqx.filter_jit(loss_fn)
    for name, get in getters:
        p = float(get(scene))
        h = rel_step * p
        plus = float(loss(eqx.tree_at(get, scene, jnp.asarray(p + h))))
        minus = float(loss(eqx.tree_at(get, scene, jnp.asarray(p - h))))
        fd = (plus - minus) / (2 * h)
        rel = abs(float(grad[name]) - fd) / abs(fd)
        assert rel < rtol, f"d/d{name}: {float(grad[name])} vs {fd}"


def central_differences(fn, p0, rel_step):
    """The central-difference Jacobian of `fn` at the parameter vector `p0`: one
    column (fn(p0 + h e_i) - fn(p0 - h e_i)) / (2 h) per parameter, h = rel_step
    p0_i, stacked on the last axis."""
    cols = []
    for i in range(p0.size):
        h = rel_step * p0[i]
        e = jnp.zeros_like(p0).at[i].set(h)
        cols.append((fn(p0 + e) - fn(p0 - e)) / (2 * h))
    return jnp.stack(cols, axis=-1)


def count_eqns(jaxpr) -> int:
    """Number of equations in a jaxpr, counting those of its sub-jaxprs."""
    n = 0
    for eqn in jaxpr.eqns:
        n += 1
        for sub in jax.core.jaxprs_in_params(eqn.params):
            n += count_eqns(sub)
    return n


class KillingPool(cf.Executor):
    """A process pool of two spawned workers in which the worker given a call
    whose array leaves `kill(leaves)` picks dies (`os._exit`), at most `times`
    times (None: every time); a fresh pool replaces a broken one. `leaves` is
    the third positional argument of the submitted call, as jaxstring's sweep and
    least_squares pass their members' arrays."""

    def __init__(self, kill, times=None):
        self.kill, self.times, self.pool = kill, times, None

    def _pool(self):
        if self.pool is None or self.pool._broken:
            self.pool = cf.ProcessPoolExecutor(
                2, mp_context=multiprocessing.get_context("spawn")
            )
        return self.pool

    def submit(self, fn, *args, **kwargs):
        if self.times != 0 and self.kill(args[2]):
            if self.times is not None:
                self.times -= 1
            return self._pool().submit(os._exit, 1)
        return self._pool().submit(fn, *args, **kwargs)

    def shutdown(self, wait=True, **kwargs):
        if self.pool is not None:
            self.pool.shutdown(wait=wait, cancel_futures=True)


def dense_jacobian(scene, y, t=0.0):
    """The vector field's Jacobian at y, dense `(n b, n b)`, by compiled jacfwd."""
    n, b = y.shape
    f = lambda v: scene.vector_field(t, v.reshape(n, b)).reshape(-1)
    return np.asarray(jax.jit(jax.jacfwd(f))(y.reshape(-1)))


def string_vf(formulation, k):
    """(vector field of (state, scene), a state 1 % off the pendulum's start, the
    scene) for the string of `k` elements in `formulation`, EA = 1e6 N."""
    scene = js.string_pendulum(formulation, k=k, EA=1e6, theta0=1.0)
    y = scene.y0 + 0.01 * jax.random.normal(jax.random.PRNGKey(0), scene.y0.shape)
    return (lambda u, s: s.vector_field(0.0, u)), y, scene


def run_on_two_cpu_devices(code: str, timeout: float = 300) -> str:
    """Run `code` (dedented) in a fresh Python process whose JAX has two CPU
    devices (the device count is fixed when JAX starts); its standard output.
    Fails the test with the end of its standard error if it fails."""
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True,
        text=True, timeout=timeout,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def run_distributed(code: str, args_of, n=2, timeout=600, alone=False) -> None:
    """Run `code` (dedented) as a `jax.distributed` job of `n` local processes on
    127.0.0.1: process i gets `sys.argv[1:]` = (coordinator address, i, *args_of(i));
    `alone`: one process outside a job, its address "alone".
    Fails the test with the end of a process's output if it fails; kills every
    process (its whole session) that is still running at the end."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{s.getsockname()[1]}"
    procs = []
    try:
        for i in range(n):
            where = "alone" if alone else address
            argv = [sys.executable, "-c", textwrap.dedent(code), where, str(i)]
            procs.append(
                subprocess.Popen(
                    argv + [str(a) for a in args_of(i)],
                    start_new_session=True,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    text=True,
                )
            )
        for p in procs:
            out, _ = p.communicate(timeout=timeout)
            assert p.returncode == 0, out[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
