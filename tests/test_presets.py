"""Accuracy presets reach the end-mass error they were chosen for, per system.

The presets (jaxstring/_presets.py) were measured at k = 40 over 2 s
(experiments/race_strongest.py --presets); here each is checked against an
independent tight reference: a small string in displacement and (eps, phi) variables
against Kvaerno5 at 1e-11 (a different solver from the presets'), and, slow-marked,
the default scene against CVODE with the numba right-hand side of
jaxstring/testing/peers.py at 1e-11, where the presets must reach their targets.
"""

import numpy as np
import pytest

import jaxstring as js
from jaxstring._presets import PRESET_TARGETS, preset_system


def _error(traj, ref_end):
    assert traj.ok, traj.status
    d = np.asarray(traj.end_mass)[1:] - np.asarray(ref_end)[1:]
    return float(np.max(np.linalg.norm(d, axis=-1)))


def _errors(scene, ts, ref_end):
    return {
        name: _error(js.simulate(scene, accuracy=name, ts=ts), ref_end)
        for name in PRESET_TARGETS
    }


@pytest.mark.parametrize(
    "formulation", ["displacement", pytest.param("angle", marks=pytest.mark.slow)]
)
def test_presets_reach_their_targets_on_a_small_string(formulation):
    scene = js.string_pendulum(formulation=formulation, k=8, EA=1e6, t1=0.5)
    assert preset_system(scene.model) == formulation
    ts = np.linspace(0.0, 0.5, 5)
    ref = js.simulate(scene, "kvaerno5", rtol=1e-11, atol=1e-11, ts=ts)
    assert ref.ok
    errors = _errors(scene, ts, ref.end_mass)
    for name, target in PRESET_TARGETS.items():
        assert errors[name] <= target, (name, errors)
    # Each preset is at least ten times more accurate than the one before.
    assert errors["balanced"] < errors["draft"] / 10, errors
    assert errors["precise"] < errors["balanced"] / 10, errors


def test_preset_systems():
    tether = js.tether_fixed(N=5)
    assert preset_system(tether.model) == "tether"
    assert preset_system(js.tandem_fishtail(t1=10.0).model) == "other"
    with pytest.raises(ValueError, match="accuracy"):
        js.simulate(tether, accuracy="exact")


@pytest.mark.slow
@pytest.mark.parametrize("formulation", ["displacement", "angle"])
def test_presets_reach_their_targets_on_the_default_scene(formulation):
    """The measurement behind the presets, repeated: k = 40, EA = 1e6, 2 s."""
    pytest.importorskip("numba")
    pytest.importorskip("sksundae")
    from jaxstring.testing import peers

    scene = js.string_pendulum(formulation=formulation)
    peer = peers.make_rhs(formulation, 40, 1e6, alpha=0.01)
    ts = np.linspace(0.0, 2.0, 5)
    jac = "analytic" if peer.jac is not None else "dq"
    out = peers.cvode_solve(peer, ts, np.ravel(scene.y0), 1e-11, 1e-11, jac=jac)
    assert out["ok"]
    errors = _errors(scene, ts, peer.end_mass(out["ys"]))
    for name, target in PRESET_TARGETS.items():
        assert errors[name] <= target, (name, errors)
