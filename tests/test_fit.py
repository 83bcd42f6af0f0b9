"""fit and gradients: derivatives against finite differences; identification of
alpha and EA from noisy positions of a finer, independently integrated string."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import optax
import pytest

import jaxstring as js
from jaxstring import _fit, _parameters
from jaxstring._adjoints import make_adjoint

from .helpers import FORMULATIONS, assert_grad_matches_central_differences


def _end_loss(traj, scene):
    # Positions of the end mass over the window and the largest strain: a loss
    # sensitive to both alpha (axial damping) and EA (stretch).
    del scene
    return jnp.sum(traj.obs["positions"][:, -1, :] ** 2) + 1e3 * jnp.max(
        traj.obs["strain"]
    )


# Natural variables repeat the displacement string's check through the written-out
# Kvaerno's forward mode (its reverse mode: tests/solvers/test_esdirk.py).
@pytest.mark.parametrize(
    "formulation",
    [f if f == "displacement" else pytest.param(f, marks=pytest.mark.slow)
     for f in FORMULATIONS],
)  # fmt: skip
def test_gradient_matches_central_differences(formulation):
    scene = js.string_pendulum(formulation=formulation, k=4, EA=1e3, alpha=0.02, t1=0.3)
    kw = dict(rtol=1e-11, atol=1e-11, n_save=11)
    _, grad = _fit.value_and_grad(
        scene, _end_loss, ["alpha", "EA"], adjoint="forward", **kw
    )
    config = _fit.SolveConfig(**kw)
    # central differences: truncation ~ (h/p)^2 = 1e-8, rounding ~ 1e-11 / 1e-4
    assert_grad_matches_central_differences(
        lambda s: _end_loss(_fit.solve(s, config), s), scene, grad
    )


@pytest.mark.slow
def test_adjoints_agree_on_the_gradient():
    # Recursive checkpointing (default) and forward mode differentiate the same
    # discretisation: they agree to rounding, not only to the solver tolerance.
    scene = js.string_pendulum(
        formulation="displacement", k=4, EA=1e3, alpha=0.02, t1=0.3
    )
    kw = dict(rtol=1e-10, atol=1e-10, n_save=11)
    _, g_fwd = _fit.value_and_grad(
        scene, _end_loss, ["alpha", "EA"], adjoint="forward", **kw
    )
    _, g_rev = _fit.value_and_grad(
        scene, _end_loss, ["alpha", "EA"], checkpoints=64, **kw
    )
    for name in ("alpha", "EA"):
        assert abs(g_rev[name] - g_fwd[name]) <= 1e-9 * abs(g_fwd[name]), name


def _bounce(formulation, k, alpha, EA, t1, eps0=0.05):
    """The pendulum hanging at rest, stretched to `eps0`, released: the end mass
    bounces on the string (its frequency carries EA, its decay alpha)."""
    base = js.string_pendulum(
        formulation=formulation, k=k, EA=EA, alpha=alpha, t1=t1, theta0=0.0
    )
    y0 = base.y0.at[:, 0].set(eps0)  # column 0: strain, in both natural forms
    return js.string_pendulum(
        formulation=formulation, k=k, EA=EA, alpha=alpha, t1=t1, theta0=0.0, y0=y0
    )


@pytest.mark.slow
def test_identify_alpha_and_EA_from_a_finer_string():
    # Data: a finer string (k = 8) in the other natural formulation (eps, t),
    # integrated by another solver (Kvaerno3 at 1e-10), 1 mm noise on the midpoint
    # and the end mass. Fit: k = 4, (eps, phi), Kvaerno5 at 1e-8. The bounce
    # converges at second order in k (k = 4 vs 8: ~2e-5 m, below the noise), so
    # the coarse model is unbiased; the horizontal release whips and is not
    # (experiments/identify_pendulum.py).
    alpha, EA, noise, t1, k_fit = 0.02, 2e3, 1e-3, 0.6, 4
    ts = jnp.linspace(0.0, t1, 121)
    truth = js.simulate(
        _bounce("natural", 2 * k_fit, alpha, EA, t1),
        "kvaerno3",
        rtol=1e-10,
        atol=1e-10,
        ts=ts,
    )
    assert truth.ok, truth.status
    clean = np.asarray(truth.positions[:, [k_fit, 2 * k_fit], :])
    data = clean + noise * np.random.default_rng(0).standard_normal(clean.shape)
    residual = js.Misfit(jnp.asarray(data), "positions", nodes=(k_fit // 2, k_fit))
    loss = lambda traj, scene: jnp.sum(residual(traj, scene) ** 2) / noise**2
    result = _fit.fit(
        _bounce("angle", k_fit, 0.7 * alpha, 1.3 * EA, t1),
        loss,
        ["alpha", "EA"],
        ts=ts,
        steps=12,
        optimizer=optax.lbfgs(),
        adjoint="forward",
        rtol=1e-8,
        atol=1e-8,
        print_every=None,
    )
    fitted = result.values()
    assert abs(fitted["alpha"] - alpha) / alpha < 0.02, fitted
    assert abs(fitted["EA"] - EA) / EA < 0.02, fitted
    # The misfit is the noise: chi^2 per residual near 1.
    assert result.losses[-1] / data.size < 1.3


def test_fit_freezes_other_leaves_and_rejects_bad_input():
    scene = js.string_pendulum(k=3, t1=0.1)
    spec = _parameters.filter_spec(scene, [_parameters.resolve(scene, "alpha")])
    assert sum(map(bool, __import__("jax").tree_util.tree_leaves(spec))) == 1
    with pytest.raises(ValueError, match="unknown parameter 'alfa'"):
        _parameters.resolve(scene, "alfa")
    with pytest.raises(ValueError, match="must be > 0"):
        _fit.fit(
            js.string_pendulum(k=3, t1=0.1, alpha=0.0),
            lambda traj, s: 0.0,
            ["alpha"],
            steps=1,
        )
    with pytest.raises(ValueError, match="unknown adjoint"):
        make_adjoint("adjoint")


@pytest.mark.parametrize(
    "positive", [pytest.param(False, marks=pytest.mark.slow), True]
)
def test_sensitivity_gradient_matches_central_differences(positive):
    # The sensitivities integrated beside the state under its error control give
    # the gradient of the same loss as differentiating the solve (central
    # differences of the solve as the reference), in the parameters' own units and
    # in log units.
    scene = js.string_pendulum(
        formulation="displacement", k=4, EA=1e3, alpha=0.02, t1=0.3
    )
    kw = dict(rtol=1e-11, atol=1e-11, n_save=11)
    # What `fit` descends: d loss / d log p where positive (log-parameters), else
    # d loss / d p.
    config = js.SolveConfig(adjoint="sensitivity", **kw)
    getters, theta, pos, frozen, config, ts = _fit._setup(
        scene, _end_loss, ["alpha", "EA"], positive, True, config, count_steps=False
    )
    _, g = _fit._jit_value_and_grad(theta, pos, frozen, _end_loss, config, True, ts)
    grad = {getter.label: float(getter(g)) for getter in getters}
    if positive:  # d/dlog p = p d/dp
        grad = {"alpha": grad["alpha"] / 0.02, "EA": grad["EA"] / 1e3}
    config = _fit.SolveConfig(**kw)
    assert_grad_matches_central_differences(
        lambda s: _end_loss(_fit.solve(s, config), s), scene, grad
    )


# Two experiments of one structure: the k = 3 pendulum released at two angles.
TS_TWO = jnp.linspace(0.0, 0.3, 11)
TIGHT = dict(rtol=1e-10, atol=1e-10)
FORWARD = dict(TIGHT, adjoint="forward")  # one parameter: forward mode


def _two_experiments(alpha):
    return [
        js.string_pendulum(k=3, EA=1e3, alpha=alpha, theta0=a, t1=0.3)
        for a in (1.2, 0.6)
    ]


class _EndMassMisfit(eqx.Module):
    """Squared end-mass misfit of an experiment against its own data, found by
    its start position."""

    data: jnp.ndarray

    def __call__(self, traj, scene):
        del scene
        i = jnp.argmin(jnp.sum((self.data[:, 0] - traj.end_mass[0]) ** 2, axis=1))
        return jnp.sum((traj.end_mass - self.data[i]) ** 2)


def _two_experiment_loss():
    ends = [js.simulate(s, ts=TS_TWO, **TIGHT).end_mass for s in _two_experiments(0.05)]
    return _EndMassMisfit(jnp.stack(ends))


def test_a_fit_of_several_experiments_sums_their_losses_and_gradients():
    loss = _two_experiment_loss()
    starts = _two_experiments(0.07)
    res = js.fit(starts, loss, ["alpha"], steps=1, ts=TS_TWO, print_every=None,
                 processes=1, **FORWARD)  # fmt: skip
    parts = [
        _fit.value_and_grad(s, loss, ["alpha"], ts=TS_TWO, **FORWARD) for s in starts
    ]
    value = sum(v for v, _ in parts)
    grad = sum(float(g["alpha"]) for _, g in parts)
    assert value > 1e-6  # the start is off the data
    assert abs(res.losses[0] - value) <= 1e-12 * value
    # the gradient in the optimised variable log(alpha): alpha dL/dalpha
    assert abs(res.grad_norm - abs(0.07 * grad)) <= 1e-9 * abs(0.07 * grad)
    assert res.processes == 1
    for kw, part in [
        (dict(scene=[starts[0], "x"]), "`scene`"),
        (dict(scene=[]), "`scene`"),
        (dict(processes=0), "`processes`"),
        (dict(simulate=False), "simulate=True"),
    ]:
        args = dict(scene=starts, loss_fn=loss, params=["alpha"]) | kw
        with pytest.raises(ValueError, match=part):
            js.fit(**args)


@pytest.mark.slow
def test_experiments_in_worker_processes_give_the_one_process_fit():
    loss = _two_experiment_loss()
    kw = dict(steps=8, optimizer=optax.lbfgs(), ts=TS_TWO, print_every=None, **FORWARD)
    one = js.fit(_two_experiments(0.07), loss, ["alpha"], processes=1, **kw)
    two = js.fit(_two_experiments(0.07), loss, ["alpha"], processes=2, **kw)
    assert two.processes == 2
    assert np.allclose(two.losses, one.losses, rtol=1e-9, atol=1e-18)
    assert abs(two.values()["alpha"] - one.values()["alpha"]) <= 1e-9
    assert abs(two.values()["alpha"] - 0.05) <= 1e-6  # the data's damping


def test_a_fit_compiles_its_step_once():
    # The start's parameter is a Python float (a weakly typed leaf) and the loss
    # holds data from a solve: the step's later calls reuse its first compilation.
    scene = js.string_pendulum(k=2, EA=1e3, alpha=0.03, t1=0.1)
    ts = jnp.linspace(0.0, 0.1, 7)
    data = js.simulate(js.string_pendulum(k=2, EA=1e3, alpha=0.02, t1=0.1), ts=ts)
    before = _fit._make_step.cache_size()
    res = js.fit(scene, _EndMassMisfit(data.end_mass[None]), ["alpha"], steps=3,
                 ts=ts, print_every=None, adjoint="forward")  # fmt: skip
    assert _fit._make_step.cache_size() - before == 1
    assert res.losses[-1] < res.losses[0]
