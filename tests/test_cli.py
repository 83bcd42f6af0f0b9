import numpy as np
import pytest

from jaxstring.cli.main import main


FAST = ["run", "string-pendulum", "--k", "6", "--EA", "1e4", "--t1", "0.3"]


def test_run_string_pendulum(tmp_path, capsys):
    code = main(FAST + ["--alpha", "0.01", "--no-rerun", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    assert "status" in out and "success" in out
    png = tmp_path / "string_pendulum.png"
    npz = tmp_path / "string_pendulum.npz"
    assert png.exists() and png.stat().st_size > 0
    assert npz.exists()
    with np.load(npz) as data:
        energy = data["energy"]
        assert energy.shape == data["ts"].shape
        assert np.all(np.isfinite(energy))
        assert bool(data["ok"])
        assert float(data["alpha"]) > 0
        # Kelvin-Voigt damping only removes energy.
        assert energy[-1] <= energy[0] + 1e-9
        assert data["positions"].shape[1:] == (7, 2)


def test_bad_input_exits_2(tmp_path, capsys):
    argv = ["run", "string-pendulum", "--EA", "-1", "--out", str(tmp_path)]
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith("error:")
    assert "EA" in err
    assert not (tmp_path / "string_pendulum.npz").exists()


def test_unknown_scene_lists_valid(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "no-such-scene"])
    assert exc.value.code == 2
    assert "string-pendulum" in capsys.readouterr().err
