"""One solve path: simulate, fit (its loss and gradient) and sweep integrate a scene
through the same `solve`, so they give the same trajectory."""

import jax.numpy as jnp
import numpy as np

import jaxstring as js


def test_simulate_fit_and_sweep_give_the_same_trajectory():
    scene = js.pendulum.string_pendulum(k=5, EA=1e4, alpha=0.02, t1=0.3)
    ts = jnp.linspace(0.0, 0.3, 7)
    kw = dict(solver="kvaerno5", rtol=1e-8, atol=1e-8, ts=ts)
    end = np.asarray(js.simulate(scene, **kw).end_mass)
    assert np.ptp(end[:, 1]) > 0.05  # it really moves

    swept = js.sweep(
        scene, {"alpha": jnp.array([0.02])}, lambda tr, s: tr.end_mass, **kw
    )
    assert bool(swept.ok.all())
    np.testing.assert_allclose(np.asarray(swept.out)[0], end, rtol=0, atol=1e-12)

    # fit's objective: the loss it descends is evaluated on the same trajectory.
    weights = jnp.arange(end.size, dtype=jnp.float64).reshape(end.shape)
    loss = lambda tr, s: jnp.sum(weights * tr.end_mass)
    value, _ = js.value_and_grad(scene, loss, ["alpha"], **kw)
    assert abs(value - float(np.sum(np.asarray(weights) * end))) < 1e-12 * max(
        1.0, abs(value)
    )


def test_a_solve_traces_the_vector_field_once(monkeypatch):
    # diffrax traces its step loop's body up to three times per solve, and a step
    # evaluates the vector field in many places (stages, Jacobians, error
    # estimate): the scene's vector field is traced once per structure, then reused
    # by every solver. (k = 13: a structure no other test of the suite solves.)
    from jaxstring import _scene

    calls = []
    vector_field = _scene.Scene.vector_field

    def counting(self, t, y):
        calls.append(t)
        return vector_field(self, t, y)

    monkeypatch.setattr(_scene.Scene, "vector_field", counting)
    scene = js.pendulum.string_pendulum(k=13, t1=0.01)
    first = js.simulate(scene, "bdf", n_save=2)
    assert first.ok and len(calls) == 1
    second = js.simulate(scene, "implicit_euler", n_save=2)
    assert second.ok and len(calls) == 1
    np.testing.assert_allclose(
        np.asarray(second.ys[-1]), np.asarray(first.ys[-1]), rtol=0, atol=1e-4
    )
