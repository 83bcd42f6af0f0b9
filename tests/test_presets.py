"""Accuracy presets deliver ordered accuracy on the stiff pendulum.

The documented errors (jaxstring/_solvers/presets.py) were measured at k = 40; here a
k = 8 string in (eps, phi) variables, EA = 1e6, 0.5 s, against Kvaerno5 at 1e-11.
"""

import jax.numpy as jnp
import numpy as np

import jaxstring as js


def test_presets_order_accuracy_against_a_tight_reference():
    scene = js.scenes.string_pendulum(formulation="angle", k=8, EA=1e6, t1=0.5)
    ts = jnp.linspace(0.0, 0.5, 26)
    ref = js.simulate(scene, "kvaerno5", rtol=1e-11, atol=1e-11, ts=ts)
    assert ref.ok
    errors = {}
    for name in ("draft", "balanced", "precise"):
        traj = js.simulate(scene, accuracy=name, ts=ts)
        assert traj.ok, (name, traj.status)
        errors[name] = float(
            np.max(np.linalg.norm(np.asarray(traj.end_mass - ref.end_mass), axis=-1))
        )
    # Bounds: ten times the errors measured at k = 40 (1.5e-4, 2.0e-6, 3.2e-10 m),
    # and each preset at least ten times more accurate than the one before.
    assert errors["draft"] < 1.5e-3, errors
    assert errors["balanced"] < 2e-5, errors
    assert errors["precise"] < 1e-8, errors
    assert errors["balanced"] < errors["draft"] / 10, errors
    assert errors["precise"] < errors["balanced"] / 10, errors
