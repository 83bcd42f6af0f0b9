"""Effects: each one is what its formula says; a left-out effect costs nothing."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js

from ..helpers import FORMULATIONS_FAST, count_eqns


def _vf_eqns(scene):
    jaxpr = jax.make_jaxpr(scene.vector_field)(0.0, scene.y0).jaxpr
    return count_eqns(jaxpr)


def _swinging_state(scene):
    """A generic state: released, then 0.05 s of motion (strained, moving)."""
    traj = js.simulate(scene, rtol=1e-8, atol=1e-8, ts=jnp.array([0.0, 0.05]))
    return traj.ys[-1]


def _eager_vf(scene, y):
    return scene.model.vector_field(jnp.asarray(0.0), y, scene.effects, scene.env)


@pytest.mark.parametrize("formulation", FORMULATIONS_FAST)
def test_left_out_effect_is_not_computed_and_changes_nothing_else(formulation):
    kw = dict(formulation=formulation, k=6, EA=1e4, t1=0.1)
    full = js.string_pendulum(
        effects=("gravity", "kelvin_voigt", "slack"), alpha=0.0, g=0.0, **kw
    )
    y = _swinging_state(js.string_pendulum(**kw))
    n_full = _vf_eqns(full)
    f_full = _eager_vf(full, y)
    for left_out in ("gravity", "kelvin_voigt", "slack"):
        names = tuple(e for e in ("gravity", "kelvin_voigt", "slack") if e != left_out)
        part = js.string_pendulum(effects=names, alpha=0.0, g=0.0, **kw)
        # Fewer operations in the compiled vector field ...
        assert _vf_eqns(part) < n_full, left_out
        # ... and, where the effect had no influence (g = 0, alpha = 0, taut
        # string), exactly the same vector field (evaluated op by op: two compiled
        # programs may order their sums differently).
        np.testing.assert_array_equal(_eager_vf(part, y), f_full)
    bare = js.string_pendulum(effects=(), **kw)
    assert _vf_eqns(bare) < min(
        _vf_eqns(js.string_pendulum(effects=(e,), **kw))
        for e in ("gravity", "kelvin_voigt", "slack")
    )


def test_gravity_is_uniform_acceleration_at_release():
    # Straight, unstrained, at rest: no tension, so every mass falls with g.
    scene = js.string_pendulum(formulation="displacement", k=8, t1=0.1)
    dy = scene.vector_field(0.0, scene.y0)
    np.testing.assert_allclose(dy[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(dy[:, 3], -9.81, rtol=1e-12)


def test_kelvin_voigt_and_slack_laws():
    kv = js.KelvinVoigt(alpha=0.02)
    eps = jnp.array([0.01, -0.01, 0.002])
    eps_dot = jnp.array([0.5, 0.1, -1.0])
    EA = 1e4
    np.testing.assert_allclose(
        kv.tension(EA * eps, eps, eps_dot, EA), EA * (eps + 0.02 * eps_dot)
    )
    slack = js.Slack()
    N = kv.tension(EA * eps, eps, eps_dot, EA)  # [150, -80, 0.0 - 180] N
    out = slack.tension(N, eps, eps_dot, EA)
    # Taut and pulling: unchanged; compressed: zero; taut but "pushing": zero.
    np.testing.assert_allclose(out, [float(N[0]), 0.0, 0.0])
    np.testing.assert_allclose(slack.elastic_strain(eps), [0.01, 0.0, 0.002])


def test_slack_string_has_zero_tension_where_compressed():
    scene = js.string_pendulum(
        formulation="displacement", k=6, effects=("gravity", "slack"), t1=0.1
    )
    y = np.array(scene.y0)
    y[:, :2] *= 0.9  # uniformly compressed by 10 %
    np.testing.assert_array_equal(scene.tension(jnp.asarray(y)), 0.0)
    y[:, :2] *= 1.01 / 0.9  # stretched by 1 %
    np.testing.assert_allclose(scene.tension(jnp.asarray(y)), 1e6 * 0.01, rtol=1e-9)


def test_same_structure_does_not_recompile_for_new_parameter_values():
    from jaxstring import _integrate

    before = _integrate.jit_solve_values.cache_size()
    for EA, alpha in ((1e4, 0.01), (2e4, 0.0), (3e4, 0.05)):
        scene = js.string_pendulum(k=5, EA=EA, alpha=alpha, t1=0.05)
        assert js.simulate(scene, ts=jnp.linspace(0, 0.05, 3)).ok
    assert _integrate.jit_solve_values.cache_size() - before <= 1


def test_other_save_times_reuse_the_compiled_solve_and_give_the_same_rows():
    # A compiled solve saves at its save times padded to the next power of two, so
    # 13 and 9 save times (both padded to 16) share one program; the steps do not
    # depend on the save times, so the rows at the common times are equal.
    from jaxstring import _integrate

    scene = js.string_pendulum(k=6, EA=1e4, alpha=0.01, t1=0.05)
    ts = jnp.linspace(0.0, 0.05, 13)
    before = _integrate.jit_solve_values.cache_size()
    full = js.simulate(scene, ts=ts)
    part = js.simulate(scene, ts=ts[:9])
    assert _integrate.jit_solve_values.cache_size() - before == 1
    assert full.ok and part.ok and part.ys.shape[0] == 9
    assert int(part.n_valid) == 9 and float(part.t_end) == float(ts[8])
    np.testing.assert_allclose(
        np.asarray(part.end_mass), np.asarray(full.end_mass[:9]), rtol=0, atol=1e-12
    )
    assert float(jnp.ptp(full.end_mass[:, 1])) > 1e-3  # it moves


@functools.cache
def _system_scenes():
    """One small scene of each system."""
    pendulum = js.pendulum.string_pendulum(k=4, t1=0.1)
    tether = js.tether.tether_fixed("exact", N=6, t1=0.1)
    tandem = js.tandem.tandem_fishtail(t1=10.0)
    return {"pendulum": pendulum, "tether": tether, "tandem": tandem}


def _foreign_effects():
    """One effect of each system (the system it belongs to, the effect)."""
    return {
        "pendulum": js.pendulum.KelvinVoigt(),
        "tether": js.tether.Drag(Cd=1.0, CdAx=0.1),
        "tandem": js.tandem.LinearDamping(),
    }


@pytest.mark.parametrize(
    "system, other",
    [
        (s, o)
        for s in ("pendulum", "tether", "tandem")
        for o in ("pendulum", "tether", "tandem")
        if s != o
    ],
)
def test_effect_of_another_system_is_refused_naming_both(system, other):
    # A scene that names an effect its model cannot apply must not run silently
    # without it: the Scene refuses it, naming the effect and the model.
    scene = _system_scenes()[system]
    effect = _foreign_effects()[other]
    model = type(scene.model).__name__
    parts = dict(model=scene.model, y0=scene.y0, t1=scene.t1, env=scene.env)
    with pytest.raises(ValueError, match=rf"{type(effect).__name__}.*{model}"):
        js.Scene(effects=scene.effects + (effect,), **parts)
    # ... while the scene's own effects are accepted as they are.
    js.Scene(effects=scene.effects, **parts)
