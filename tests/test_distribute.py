"""Sweeps over worker processes, executors and jax.distributed: the same members
give the same results wherever they run, a worker that dies loses no member, and
bad settings are refused by name. Local processes only (127.0.0.1), bounded in
time, cleaned up."""

import concurrent.futures as cf
import os
import signal
import socket
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import jaxstring as js
from jaxstring import _distribute

from .helpers import KillingPool


ALPHAS = np.linspace(0.005, 0.05, 8)
SOLVE = {"solver": "implicit_euler_fixed", "dt0": 0.01}


def _scene():
    return js.string_pendulum(k=4, t1=0.2)


def _sweep(**kw):
    # Groups of 2: the 8 members make chunks for two workers and blocks for two
    # distributed processes.
    # (Fixed-step implicit Euler: the cheapest of the implicit solves to compile,
    # in this process and in each distributed one.)
    kw = {"batch_size": 2} | kw
    return js.sweep(_scene(), {"alpha": ALPHAS}, n_save=5, **(SOLVE | kw))


@pytest.fixture(scope="module")
def one_process():
    return _sweep(processes=1)


def _same(a, b):
    assert list(a.values["alpha"]) == list(b.values["alpha"])
    np.testing.assert_array_equal(a.result, b.result)
    for key in a.out:
        np.testing.assert_allclose(a.out[key], b.out[key], rtol=1e-12, atol=1e-12)


# Worker processes also run in the default run's test_least_squares (a fit over a
# worker process); this sweep repeats them.
@pytest.mark.slow
def test_two_worker_processes_give_the_one_process_results(one_process):
    two = _sweep(processes=2)
    assert two.processes == 2 and two.ok.all()
    _same(one_process, two)
    # In another order the members come back where they were given.
    both = _sweep(processes=2, order="sort")
    _same(one_process, both)


def _kill_chunk(value, times):
    """A pool that kills the worker running the chunk whose first member value is
    `value`, `times` times."""
    return KillingPool(lambda leaves: float(leaves[0][0]) == value, times)


@pytest.mark.slow
def test_members_of_a_dead_worker_are_run_again(one_process):
    with _kill_chunk(ALPHAS[0], times=1) as executor:
        again = _sweep(executor=executor)
    assert again.ok.all()
    _same(one_process, again)


@pytest.mark.slow
def test_a_chunk_that_keeps_failing_carries_a_clear_status(one_process):
    # A worker running the first chunk dies every time (in parallel twice, then on
    # its own): that chunk's members fail, with a status that says so; the chunks
    # lost with it (a dead worker breaks the pool) are run again and succeed.
    with _kill_chunk(ALPHAS[0], times=3) as executor:
        res = _sweep(executor=executor)
    lost = ~res.ok
    assert lost[0] and lost.sum() < len(ALPHAS), res.status
    assert all(res.result[lost] == _distribute.WORKER_FAILED)
    assert all(
        s.startswith("worker process failed") for s, b in zip(res.status, lost) if b
    )
    assert np.all(np.isnan(res.out["positions"][lost]))
    np.testing.assert_allclose(
        res.out["positions"][~lost], one_process.out["positions"][~lost], rtol=1e-12
    )


@pytest.mark.parametrize(
    "kw, parts",
    [
        (dict(processes=0), ["`processes`", "0", ">= 1"]),
        (dict(processes=2.5), ["`processes`", "2.5"]),
        (dict(executor="pool"), ["`executor`", "'pool'", "Executor"]),
        (
            dict(processes=2, executor=cf.ThreadPoolExecutor(1)),
            ["`processes` or `executor`"],
        ),
    ],
)
def test_bad_settings_are_refused_by_name(kw, parts):
    with pytest.raises(ValueError) as info:
        _sweep(**kw)
    for part in parts:
        assert part in str(info.value)


_DISTRIBUTED = textwrap.dedent(
    """
    import sys
    import jax
    jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2,
                               process_id=int(sys.argv[2]),
                               initialization_timeout=120)
    import numpy as np
    import jaxstring as js
    res = js.sweep(js.string_pendulum(k=4, t1=0.2),
                   {"alpha": np.linspace(0.005, 0.05, 8)}, n_save=5,
                   solver="implicit_euler_fixed", dt0=0.01, batch_size=2,
                   processes=1)
    np.savez(sys.argv[3], result=res.result, **res.out)
    jax.distributed.shutdown()
    """
)


def _free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_two_distributed_processes_give_the_one_process_results(tmp_path, one_process):
    address = f"127.0.0.1:{_free_port()}"
    procs = []
    try:
        for i in range(2):
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-c",
                        _DISTRIBUTED,
                        address,
                        str(i),
                        str(tmp_path / f"p{i}.npz"),
                    ],  # fmt: skip
                    start_new_session=True,
                    stdout=subprocess.PIPE,
                    stderr=subprocess.STDOUT,
                    text=True,
                )
            )
        for p in procs:
            out, _ = p.communicate(timeout=600)
            assert p.returncode == 0, out[-3000:]
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
    for i in range(2):
        got = np.load(tmp_path / f"p{i}.npz")
        np.testing.assert_array_equal(got["result"], one_process.result)
        for key in one_process.out:
            np.testing.assert_allclose(
                got[key], one_process.out[key], rtol=1e-12, atol=1e-12
            )


_UNGUARDED = """
import sys
import numpy as np
import jaxstring as js
res = js.sweep(js.string_pendulum(k=4, t1=0.2), {"alpha": np.linspace(0.005, 0.05, 8)},
               solver="bdf", n_save=5, batch_size=2, processes=2)
np.savez(sys.argv[1], result=res.result, **res.out)
"""


@pytest.mark.slow
def test_a_script_without_a_main_guard_is_not_run_again_by_the_workers(
    tmp_path, one_process
):
    # Spawned processes import the parent's main script; jaxstring's workers must
    # not (the script would start its sweep again in each worker).
    script = tmp_path / "unguarded.py"
    script.write_text(_UNGUARDED)
    out = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "r.npz")],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert "Traceback" not in out.stderr, out.stderr[-3000:]
    got = np.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(got["result"], one_process.result)
    for key in one_process.out:
        np.testing.assert_allclose(
            got[key], one_process.out[key], rtol=1e-12, atol=1e-12
        )


@pytest.mark.parametrize("solver", ["bdf", "implicit_euler_fixed"])
def test_sweep_programs_export_without_host_callbacks(solver):
    # Worker processes run the exported program; JAX cannot export host callbacks
    # (diffrax's run-time checks compile to them where the scene's span is traced).
    from jaxstring._sweep import _sweep_local

    scene = _scene()
    config = js.SolveConfig(solver=solver, dt0=0.01, n_save=5)
    ts = config.save_times(scene.t0, scene.t1)
    getters = (js._fit.resolve(scene, "alpha"),)
    args = ((ALPHAS[:2],), scene, getters, lambda traj, s: traj.end_mass, config, ts, 2)
    key, program, leaves, outputs = _distribute.export_chunk(_sweep_local, args)
    assert len(program) > 0 and outputs is not None


@pytest.mark.slow
def test_group_size_fits_the_free_memory():
    # The group chosen for a device with a given free memory: its program's planned
    # memory (XLA's memory analysis) fits the budget, one member more would not.
    import jax

    from jaxstring._sweep import _sweep_local

    scene = _scene()
    config = js.SolveConfig(solver="bdf", n_save=5)
    ts = config.save_times(scene.t0, scene.t1)
    getters = (js._fit.resolve(scene, "alpha"),)
    vals = (np.linspace(0.005, 0.05, 64),)
    args = (vals, scene, getters, lambda traj, s: traj.end_mass, config, ts, 64)
    device = jax.devices()[0]

    def at(m):
        return _distribute.program_bytes(
            _sweep_local, ((vals[0][:m],),) + args[1:], device
        )

    free = 3 * at(4)
    g = _distribute.fit_group(_sweep_local, args, 64, device, free_bytes=free)
    assert 4 < g < 64
    assert at(g) <= 0.8 * free * 1.02  # linear in the group size, to 2 %
    assert at(g + 2) > 0.8 * free * 0.98
