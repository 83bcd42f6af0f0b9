"""Sweeps over worker processes, executors and jax.distributed: the same members
give the same results wherever they run, a worker that dies loses no member, and
bad settings are refused by name. Local processes only (127.0.0.1), bounded in
time, cleaned up."""

import concurrent.futures as cf
import multiprocessing
import os
import subprocess
import sys
import textwrap
import time

import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _distribute, _sweep as sweep_module
from jaxstring._parameters import resolve

from .helpers import KillingPool, run_distributed


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


@pytest.mark.slow
@pytest.mark.skipif(_distribute.host_cores() < 2, reason="one core: no workers")
def test_an_auto_sweep_that_ran_briefly_in_a_pool_runs_here_next(
    one_process, tmp_path, monkeypatch
):
    # "auto" sends a sweep of enough members to a pool, a worker per core, whose
    # workers keep the chunks' run time beside their executable. Where the chunks
    # ran for less than a pool takes to start (milliseconds here), a process with
    # no pool running (a later one) runs them itself on that executable.
    from jaxstring import _programs

    monkeypatch.setattr(sweep_module, "AUTO_MEMBERS_PER_CORE", 1)
    monkeypatch.setitem(_distribute._RUN_HERE, "s", 0.0)
    monkeypatch.setattr(_distribute, "_EXPORTED", {})  # saved in the folder anew
    pool = dict(_distribute._POOL)
    _distribute._POOL.update(executor=None, workers=0)
    _programs.set_program_folder(str(tmp_path))
    try:
        pooled = _sweep(processes="auto")
        _distribute.shutdown_pool()
        here = _sweep(processes="auto")
        started = _distribute._POOL["executor"] is not None
    finally:
        _programs.set_program_folder(None)
        _distribute.shutdown_pool()
        _distribute._POOL.update(pool)
    assert pooled.processes == _distribute.host_cores()
    assert here.processes == 1 and not started
    for res in (pooled, here):
        assert res.ok.all()
        _same(one_process, res)


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


def test_two_distributed_processes_give_the_one_process_results(tmp_path, one_process):
    run_distributed(_DISTRIBUTED, lambda i: [tmp_path / f"p{i}.npz"])
    for i in range(2):
        got = np.load(tmp_path / f"p{i}.npz")
        np.testing.assert_array_equal(got["result"], one_process.result)
        for key in one_process.out:
            np.testing.assert_allclose(
                got[key], one_process.out[key], rtol=1e-12, atol=1e-12
            )


# The members and settings of `_sweep` (`SOLVE` written in), from a script with no
# main guard.
_UNGUARDED = f"""
import sys
import jax.numpy as jnp
import numpy as np
import jaxstring as js
alphas = np.linspace(0.005, 0.05, 8)
res = js.sweep(js.string_pendulum(k=4, t1=0.2), {{"alpha": alphas}},
               n_save=5, batch_size=2, processes=2, **{SOLVE!r})
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
    getters = (resolve(scene, "alpha"),)
    args = ((ALPHAS[:2],), scene, getters, lambda traj, s: traj.end_mass, config, ts, 2)
    key, program, leaves, outputs = _distribute.export_chunk(_sweep_local, args)
    assert len(program) > 0 and outputs is not None


def test_a_sweep_program_is_saved_and_a_later_process_reads_it(tmp_path, monkeypatch):
    # The chunk program of a sweep with jaxstring's default output is saved in the
    # program folder; a later process (JAX's and the export's in-memory caches
    # cleared) reads it without tracing, and it gives the same members' results.
    import jax

    from jaxstring import _programs, _worker
    from jaxstring._sweep import _default_fn, _sweep_local

    scene = _scene()
    config = js.SolveConfig(solver="implicit_euler_fixed", dt0=0.01, n_save=5)
    ts = config.save_times(scene.t0, scene.t1)
    getters = (resolve(scene, "alpha"),)
    args = ((ALPHAS[:2],), scene, getters, _default_fn, config, ts, 2)
    custom = args[:3] + (lambda traj, s: traj.end_mass,) + args[4:]
    _programs.set_program_folder(str(tmp_path))
    _distribute._EXPORTED.clear()  # exported by an earlier test of this process
    try:
        key, program, leaves, _ = _distribute.export_chunk(_sweep_local, args)
        _distribute.export_chunk(_sweep_local, custom)  # a lambda: not saved
        assert len(list(tmp_path.glob("*.program"))) == 1
        first = _worker.run(key, program, [np.asarray(x) for x in leaves])
        jax.clear_caches()
        _distribute._EXPORTED.clear()
        _programs._KEYS.clear()
        _worker._COMPILED.clear()

        def no_tracing(*a, **k):
            raise AssertionError("the saved sweep program was traced again")

        monkeypatch.setattr(jax.export, "export", no_tracing)
        key2, program2, leaves2, _ = _distribute.export_chunk(_sweep_local, args)
        again = _worker.run(key2, program2, [np.asarray(x) for x in leaves2])
    finally:
        _programs.set_program_folder(None)
    out, codes, _ = first
    assert np.all(codes == 0)
    # The members' swings differ (alpha 0.005 and 0.0114) and come back identical.
    assert not np.allclose(out["tension"][0], out["tension"][1], rtol=1e-6, atol=0)
    for a, b in zip(jax.tree.leaves(first), jax.tree.leaves(again)):
        np.testing.assert_array_equal(a, b)


@pytest.mark.slow
def test_group_size_fits_the_free_memory():
    # The group chosen for a device with a given free memory: its program's planned
    # memory (XLA's memory analysis) fits the budget, one member more would not.
    import jax

    from jaxstring._sweep import _sweep_local

    scene = _scene()
    config = js.SolveConfig(solver="bdf", n_save=5)
    ts = config.save_times(scene.t0, scene.t1)
    getters = (resolve(scene, "alpha"),)
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


_IDENTIFY = textwrap.dedent(
    """
    import sys
    import jax
    if sys.argv[1] != "alone":
        jax.distributed.initialize(coordinator_address=sys.argv[1], num_processes=2,
                                   process_id=int(sys.argv[2]),
                                   initialization_timeout=120)
    import equinox as eqx
    import jax.numpy as jnp
    import numpy as np
    import jaxstring as js

    TS = np.linspace(0.0, 0.2, 9)

    def scene(k, **kw):
        return js.string_pendulum(k=k, t1=0.2, theta0=1.0, **(dict(EA=1e3) | kw))

    class Misfit(eqx.Module):
        data: tuple  # end-mass data of the 2- and the 3-element experiment

        def __call__(self, traj, scene):
            return (traj.end_mass - self.data[scene.model.k - 2]).ravel()

    truth = [scene(2, alpha=0.05), scene(3, alpha=0.05)]
    misfit = Misfit(tuple(js.simulate(s, ts=TS).end_mass for s in truth))
    starts = [scene(2, EA=1.4e3, alpha=0.03), scene(3, EA=1.4e3, alpha=0.03)]
    ls = js.least_squares(starts, misfit, ["alpha", "EA"], ts=TS, processes=1)
    fit = js.fit(starts, lambda traj, sc: jnp.sum(misfit(traj, sc) ** 2), ["alpha"],
                 steps=3, ts=TS, processes=1, print_every=None)
    np.savez(sys.argv[3], values=[ls.values["alpha"], ls.values["EA"]],
             cost=ls.cost, iterations=ls.iterations, converged=ls.converged,
             losses=fit.losses, alpha=fit.values()["alpha"])
    if sys.argv[1] != "alone":
        jax.distributed.shutdown()
    """
)


@pytest.mark.slow
def test_identification_over_two_distributed_processes_gives_the_one_process_fit(
    tmp_path,
):
    # Two experiments of different structures (2 and 3 elements): each process of
    # the job evaluates one and gathers the other, so both run the iteration of one
    # process, which solves them one after the other.
    run_distributed(_IDENTIFY, lambda i: [tmp_path / f"p{i}.npz"])
    run_distributed(_IDENTIFY, lambda i: [tmp_path / "alone.npz"], n=1, alone=True)
    one = np.load(tmp_path / "alone.npz")
    assert one["converged"]
    np.testing.assert_allclose(one["values"], [0.05, 1e3], rtol=1e-6)
    for i in range(2):
        got = np.load(tmp_path / f"p{i}.npz")
        assert got["converged"]
        np.testing.assert_allclose(got["values"], one["values"], rtol=1e-10)
        # The same steps, but for the last: rounding may stop one step earlier.
        assert abs(int(got["iterations"]) - int(one["iterations"])) <= 1
        np.testing.assert_allclose(got["losses"], one["losses"], rtol=1e-9)
        assert abs(float(got["alpha"]) - float(one["alpha"])) <= 1e-9


@pytest.mark.skipif(_distribute.host_cores() < 2, reason="one core: nothing to bind")
def test_a_pool_with_a_worker_per_core_binds_each_to_a_core_of_its_own():
    cores = _distribute.host_cores()
    _distribute.shutdown_pool()
    before = {p.pid for p in multiprocessing.active_children()}
    pool = _distribute.process_pool(cores)
    try:
        # Every worker busy at once: the pool has started (and set up) all of them.
        list(pool.map(time.sleep, [1.0] * cores, timeout=120))
        workers = [p for p in multiprocessing.active_children() if p.pid not in before]
        assert len(workers) == cores
        bound = [sorted(os.sched_getaffinity(p.pid)) for p in workers]
        assert all(len(b) == 1 for b in bound)
        assert sorted(b[0] for b in bound) == _distribute.pinned_cores(cores)
        # Every thread of a worker (XLA's too) is on the worker's core.
        for p, b in zip(workers, bound):
            tids = [int(t) for t in os.listdir(f"/proc/{p.pid}/task")]
            assert len(tids) > 1
            assert all(sorted(os.sched_getaffinity(t)) == b for t in tids)
        # Fewer workers than cores: the system places them.
        assert _distribute.pinned_cores(cores - 1) is None
    finally:
        _distribute.shutdown_pool()


def test_workers_compile_a_program_once_and_read_it_from_the_cache(tmp_path):
    # The first worker to take a program compiles it under a file lock; another
    # waits for the lock and then reads the compilation from the cache, and once
    # the program is marked compiled nobody waits.
    import fcntl
    import threading

    import jax

    from jaxstring import _worker

    cpu = jax.local_devices(backend="cpu")[0]
    x = jax.device_put(np.linspace(0.0, 1.0, 5), cpu)
    lowered = jax.jit(lambda x: jnp.cumsum(jnp.sin(x) ** 2)).lower(x)
    cache, key = str(tmp_path), "k" * 32
    folder = tmp_path / "jaxstring-compiling"
    folder.mkdir()
    finished = []
    with open(folder / f"{key}.lock", "a") as held:  # a worker compiling it
        fcntl.flock(held, fcntl.LOCK_EX)
        waiter = threading.Thread(
            target=lambda: finished.append(_worker._compile(lowered, key, cache))
        )
        waiter.start()
        waiter.join(timeout=1.0)
        assert waiter.is_alive() and not finished  # waits for the lock
        (folder / f"{key}.done").touch()  # compiled, then released
        fcntl.flock(held, fcntl.LOCK_UN)
    waiter.join(timeout=60)
    assert len(finished) == 1
    expected = np.cumsum(np.sin(np.linspace(0.0, 1.0, 5)) ** 2)
    np.testing.assert_allclose(np.asarray(finished[0](x)), expected, rtol=1e-15)
    # Marked compiled: a held lock does not stop another worker.
    with open(folder / f"{key}.lock", "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        np.testing.assert_allclose(
            np.asarray(_worker._compile(lowered, key, cache)(x)), expected, rtol=1e-15
        )
    # A new program: the first worker compiles it and marks it compiled.
    other = "m" * 32
    np.testing.assert_allclose(
        np.asarray(_worker._compile(lowered, other, cache)(x)), expected, rtol=1e-15
    )
    assert (folder / f"{other}.done").exists()


_WORKER_RUN = """
import pickle, sys
import numpy as np
from jaxstring import _worker

cache, key, program_file, mode = sys.argv[1:]
_worker.init(cache)
program = open(program_file, "rb").read() if mode == "compile" else b"not a program"
a = np.array([[4.0, 1.0, 0.5], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
b = np.array([1.0, 2.0, 3.0])
out = _worker.run(key, program, [a, b])
print(repr(np.asarray(out["x"]).tolist()))
"""


def test_a_later_worker_runs_the_executable_an_earlier_one_saved(tmp_path):
    # A worker compiles a chunk program (an LU solve: LAPACK) and saves its
    # executable in the cache's `programs` folder; a worker of a later pool (a
    # fresh process) runs the executable without unpickling the program.
    import ast
    import dataclasses
    import os
    import pickle
    import subprocess
    import sys

    import jax

    def solve(a, b):
        return {"x": jnp.linalg.solve(a, b)}

    avals = [jax.ShapeDtypeStruct((3, 3), jnp.float64),
             jax.ShapeDtypeStruct((3,), jnp.float64)]  # fmt: skip
    exported = jax.export.export(jax.jit(solve), platforms=("cpu",))(*avals)
    program = tmp_path / "program"
    program.write_bytes(pickle.dumps(dataclasses.replace(exported, _get_vjp=None)))
    (tmp_path / "run.py").write_text(_WORKER_RUN)
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    cache = tmp_path / "cache"

    def worker(mode):
        run = subprocess.run(
            [sys.executable, str(tmp_path / "run.py"), str(cache), "k" * 32,
             str(program), mode],
            env=env, capture_output=True, text=True, timeout=120,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr[-2000:]
        return ast.literal_eval(run.stdout.splitlines()[-1])

    first = worker("compile")
    assert len(list((cache / "programs").glob("*.full.executable"))) == 1
    second = worker("load")
    a = np.array([[4.0, 1.0, 0.5], [2.0, 3.0, 1.0], [0.0, 1.0, 5.0]])
    np.testing.assert_allclose(second, np.linalg.solve(a, [1.0, 2.0, 3.0]), rtol=1e-14)
    assert first == second
