"""sweep: one compiled vmap over members equals a Python loop of simulate calls;
a failed member leaves the others intact; sharding over two CPU devices."""

import os
import subprocess
import sys
import textwrap

import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring._sweep import sweep


def _end_and_tension(traj, scene):
    del scene
    return {
        "end": traj.obs["positions"][:, -1, :],
        "T_max": jnp.max(traj.obs["tension"]),
    }


KW = dict(rtol=1e-9, atol=1e-9, n_save=11)


def test_sweep_matches_loop_of_simulate_calls():
    base = js.scenes.string_pendulum(
        formulation="displacement", k=3, EA=1e3, alpha=0.02, t1=0.2
    )
    alphas = np.linspace(0.005, 0.05, 4)
    EAs = np.array([5e2, 1e3, 2e3, 4e3])
    res = sweep(base, {"alpha": alphas, "EA": EAs}, _end_and_tension, devices=1, **KW)
    assert res.ok.all(), res.status
    for i, (a, ea) in enumerate(zip(alphas, EAs)):
        scene = js.scenes.string_pendulum(
            formulation="displacement", k=3, EA=ea, alpha=a, t1=0.2
        )
        traj = js.simulate(scene, **KW)
        ref = _end_and_tension(traj, scene)
        assert np.max(np.abs(res.out["end"][i] - np.asarray(ref["end"]))) < 1e-10
        assert abs(res.out["T_max"][i] - float(ref["T_max"])) < 1e-10 * float(
            ref["T_max"]
        )
        assert int(res.stats["num_steps"][i]) == int(traj.stats["num_steps"])


def test_failed_member_leaves_the_others_intact():
    base = js.scenes.string_pendulum(
        formulation="displacement", k=3, EA=1e3, alpha=0.02, t1=0.2
    )
    EAs = np.array([1e3, 1e8, 2e3])  # the stiff member needs far more steps
    res = sweep(base, {"EA": EAs}, _end_and_tension, devices=1, max_steps=400, **KW)
    assert res.ok.tolist() == [True, False, True], res.status
    assert "max_steps" in res.status[1] or "maximum" in res.status[1].lower()
    for i in (0, 2):
        scene = js.scenes.string_pendulum(
            formulation="displacement", k=3, EA=EAs[i], alpha=0.02, t1=0.2
        )
        ref = js.simulate(scene, max_steps=400, **KW)
        assert np.max(np.abs(res.out["end"][i] - np.asarray(ref.end_mass))) < 1e-10
    # The failed member keeps its valid rows and NaN after the failure.
    assert np.isnan(res.out["end"][1][-1]).all()


@pytest.mark.slow
def test_grid_shape_and_sharding_over_two_cpu_devices():
    # A fresh process: the device count is fixed when JAX starts.
    code = textwrap.dedent(
        """
        import numpy as np, jax, jax.numpy as jnp
        import jaxstring as js
        from jaxstring._sweep import sweep
        assert len(jax.devices()) == 2
        base = js.scenes.string_pendulum(k=3, EA=1e3, alpha=0.02, t1=0.2)
        fn = lambda traj, s: traj.obs["positions"][-1, -1, :]
        kw = dict(rtol=1e-9, atol=1e-9, n_save=11)
        v = {"alpha": [0.01, 0.02, 0.04], "EA": [1e3, 2e3]}
        two = sweep(base, v, fn, grid=True, **kw)
        one = sweep(base, v, fn, grid=True, devices=1, **kw)
        assert two.n_devices == 2 and two.shape == (3, 2), (two.n_devices, two.shape)
        assert two.out.shape == (3, 2, 2)
        print(float(np.max(np.abs(two.out - one.out))))
        """
    )
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2")
    out = subprocess.run(
        [sys.executable, "-c", code],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert float(out.stdout.strip().splitlines()[-1]) < 1e-12
