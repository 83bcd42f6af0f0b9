"""Bad input raises ValueError at construction, naming the argument."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js


def pendulum(**kw):
    return js.string_pendulum(**kw)


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(l=0.0), "`l`"),
        (dict(l=-1.0), "`l`"),
        (dict(mu=0.0), "`mu`"),
        (dict(m_s=-2.0), "`m_s`"),
        (dict(EA=0.0), "`EA`"),
        (dict(EA=float("nan")), "`EA`"),
        (dict(alpha=-0.1), "`alpha`"),
        (dict(k=1), "`k`"),
        (dict(k=2.5), "`k`"),
        (dict(formulation="natrual"), "formulation"),
        (dict(effects=("gravity", "drag")), "effect"),
        (dict(theta0=float("nan")), "`theta0`"),
        (dict(t1=0.0), "`t1`"),
        (dict(dim=4), "`dim`"),
        (dict(formulation="angle", dim=3), "`dim`"),
        (dict(g=-9.81), "`g`"),
    ],
)
def test_scene_arguments(kw, name):
    with pytest.raises(ValueError, match=name):
        pendulum(**kw)


def test_nan_initial_state():
    y0 = np.array(pendulum(k=4).y0)
    y0[2, 0] = np.nan
    with pytest.raises(ValueError, match="`y0`"):
        pendulum(k=4, y0=jnp.asarray(y0))


def test_initial_state_of_wrong_shape():
    with pytest.raises(ValueError, match="`y0`"):
        pendulum(k=4, y0=jnp.zeros((3, 4)))


def test_models_validate_directly():
    with pytest.raises(ValueError, match="`EA`"):
        js.DisplacementString(l=1.0, mu=1.0, m_s=1.0, EA=-5.0, k=4)
    with pytest.raises(ValueError, match="`k`"):
        js.NaturalTangentString(l=1.0, mu=1.0, m_s=1.0, EA=1.0, k=1)


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(solver="kvaerno6"), "solver"),
        (dict(rtol=0.0), "`rtol`"),
        (dict(atol=-1e-6), "`atol`"),
        (dict(max_steps=0), "`max_steps`"),
        (dict(dt0=-0.1), "`dt0`"),
        (dict(ts=jnp.array([0.0, 0.2, 0.1])), "`ts`"),
        (dict(ts=jnp.array([0.0, 5.0])), "`ts`"),
    ],
)
def test_simulate_arguments(kw, name):
    scene = pendulum(k=4, t1=1.0)
    with pytest.raises(ValueError, match=name):
        js.simulate(scene, **kw)


def test_message_states_valid_range():
    with pytest.raises(ValueError, match=r"> 0"):
        pendulum(EA=-1.0)
    with pytest.raises(ValueError, match="kvaerno5"):
        js.simulate(pendulum(k=4), solver="rk4")


def test_unknown_accuracy_preset():
    with pytest.raises(ValueError, match="accuracy"):
        js.simulate(pendulum(k=4), accuracy="exact")
