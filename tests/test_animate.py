"""Animations: each system's GIF shows its trajectory (frames drawn from the saved
states), and importing a plot module leaves the user's matplotlib backend alone."""

import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

import jaxstring as js
from jaxstring.cli.main import main


def _frames(path):
    with Image.open(path) as im:
        return im.n_frames


def test_pendulum_animation_ends_at_the_end_mass(tmp_path):
    from jaxstring.pendulum import plot

    scene = js.pendulum.string_pendulum(k=4, EA=1e4, t1=0.2)
    traj = js.simulate(scene, "bdf", ts=jnp.linspace(0.0, 0.2, 21))
    ts, pos = plot.animation_frames(traj, frames=8)
    assert len(ts) == 8 and ts[0] == 0.0 and ts[-1] == pytest.approx(0.2)
    # the last frame's drawn string ends at the trajectory's last end-mass position
    np.testing.assert_array_equal(pos[-1, -1], np.asarray(traj.end_mass)[-1])
    np.testing.assert_array_equal(pos[:, 0], 0.0)  # pivot fixed
    path = plot.animate(traj, str(tmp_path / "p.gif"), frames=8)
    assert _frames(path) == 8


@pytest.mark.slow
def test_tether_animation_draws_the_cable(tmp_path):
    from jaxstring.tether import plot

    scene = js.tether.tether_fixed("exact", N=6, t1=0.2)
    traj = js.simulate(scene, "dopri5", ts=jnp.linspace(0.0, 0.2, 11))
    ts, nodes = plot.animation_frames(traj, frames=5)
    assert nodes.shape == (5, 8, 3)
    np.testing.assert_array_equal(nodes[-1, 1:-1], np.asarray(traj.positions)[-1])
    path = plot.animate(traj, str(tmp_path / "t.gif"), frames=5)
    assert _frames(path) == 5


@pytest.mark.slow
def test_tandem_animation_draws_the_vessels(tmp_path):
    from jaxstring.tandem import plot

    scene = js.tandem.tandem_fishtail(t1=200.0)
    traj = js.simulate(scene, "kvaerno5", ts=jnp.linspace(0.0, 200.0, 11))
    ts, states, fairleads = plot.animation_frames(traj, frames=4)
    assert states.shape == (4, 2, 6)
    np.testing.assert_array_equal(states[-1].reshape(-1), np.asarray(traj.ys)[-1])
    np.testing.assert_array_equal(fairleads[-1], np.asarray(traj.fairleads)[-1])
    path = plot.animate(traj, scene.model, str(tmp_path / "v.gif"), frames=4)
    assert _frames(path) == 4


@pytest.mark.slow
def test_cli_animate_writes_a_gif(tmp_path, capsys):
    argv = ["run", "string-pendulum", "--k", "4", "--EA", "1e4", "--t1", "0.2"]
    code = main(
        argv + ["--no-cache", "--animate", "--frames", "6", "--out", str(tmp_path)]
    )
    assert code == 0
    gif = tmp_path / "string_pendulum.gif"
    assert f"wrote {gif}" in capsys.readouterr().out
    assert _frames(gif) == 6


def test_cli_rejects_too_few_frames(tmp_path, capsys):
    argv = [
        "run",
        "string-pendulum",
        "--animate",
        "--frames",
        "1",
        "--out",
        str(tmp_path),
    ]
    assert main(argv) == 2
    assert "--frames" in capsys.readouterr().err


def test_plot_modules_leave_the_backend_alone():
    code = (
        "import matplotlib; matplotlib.use('svg');"
        "import jaxstring.pendulum.plot, jaxstring.tether.plot, jaxstring.tandem.plot;"
        "print(matplotlib.get_backend())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip().lower() == "svg"
