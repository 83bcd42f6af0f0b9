"""least_squares: Levenberg-Marquardt with forward-mode Jacobians through the solver
recovers known parameters, reports a Gauss-Newton covariance that matches finite
differences, fits several experiments at once, and refuses bad input up front."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring._distribute import host_cores

from .helpers import KillingPool


TS = jnp.linspace(0.0, 0.3, 16)
TRUTH = dict(EA=1e3, alpha=0.05)


def _scene(theta0=np.pi / 2, **kw):
    p = dict(TRUTH, **kw)
    return js.pendulum.string_pendulum(
        "displacement", k=4, EA=p["EA"], alpha=p["alpha"], t1=0.3, theta0=theta0
    )


@functools.cache
def _data(theta0=np.pi / 2):
    # Another solver at a tight tolerance: the data's own integration error (~1e-10 m)
    # is far below what the fit resolves.
    traj = js.simulate(_scene(theta0), "rodas5p", rtol=1e-11, atol=1e-11, ts=TS)
    return np.asarray(traj.end_mass)


@pytest.fixture(scope="module")
def one_process_fit():
    start = _scene(EA=1.4e3, alpha=0.03)
    return js.least_squares(start, js.Misfit(_data()), ["alpha", "EA"], ts=TS)


def test_recovers_known_parameters_from_a_start_40_percent_off(one_process_fit):
    res = one_process_fit
    assert res.converged, res.message
    assert res.values["alpha"] == pytest.approx(TRUTH["alpha"], rel=1e-4)
    assert res.values["EA"] == pytest.approx(TRUTH["EA"], rel=1e-4)
    assert res.cost < 1e-6 * res.cost_start
    assert res.iterations < 30  # Levenberg-Marquardt, not hundreds of Adam steps
    assert float(res.scene.model.EA) == pytest.approx(res.values["EA"])


def test_covariance_is_the_gauss_newton_one_with_a_finite_difference_jacobian():
    rng = np.random.default_rng(3)
    sigma = 1e-4
    noisy = _data() + sigma * rng.standard_normal(_data().shape)
    res = js.least_squares(
        _scene(), js.Misfit(noisy), ["alpha", "EA"], ts=TS, sigma=sigma
    )
    assert res.converged, res.message

    def residuals(alpha, EA):
        sc = _scene(alpha=alpha, EA=EA)
        traj = js.simulate(sc, "kvaerno5", rtol=1e-8, atol=1e-8, ts=TS)
        return np.asarray(js.Misfit(noisy)(traj, sc)).ravel()

    a, e = res.values["alpha"], res.values["EA"]
    ha, he = 1e-4 * a, 1e-4 * e
    J = np.stack(
        [
            (residuals(a + ha, e) - residuals(a - ha, e)) / (2 * ha),
            (residuals(a, e + he) - residuals(a, e - he)) / (2 * he),
        ],
        axis=1,
    )
    cov = sigma**2 * np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(res.cov, cov, rtol=1e-3)
    assert res.std["alpha"] == pytest.approx(np.sqrt(cov[0, 0]), rel=1e-3)


@pytest.mark.slow
def test_two_experiments_share_the_parameters():
    starts = [_scene(EA=0.7e3, alpha=0.07), _scene(3 * np.pi / 8, EA=0.7e3, alpha=0.07)]
    residual = _TwoData(jnp.asarray(_data()), jnp.asarray(_data(3 * np.pi / 8)))
    res = js.least_squares(starts, residual, ["alpha", "EA"], ts=TS)
    assert res.converged, res.message
    assert res.values["alpha"] == pytest.approx(TRUTH["alpha"], rel=1e-4)
    assert res.values["EA"] == pytest.approx(TRUTH["EA"], rel=1e-4)
    assert len(res.scenes) == 2
    assert float(res.scenes[1].model.EA) == pytest.approx(res.values["EA"])


class _TwoData(eqx.Module):
    """Each experiment compared with its own data (told apart by the release angle)."""

    a: jnp.ndarray
    b: jnp.ndarray

    def __call__(self, traj, scene):
        first = jnp.abs(scene.y0[-1, 1]) < 1e-12  # released horizontally: y = 0
        data = jnp.where(first, self.a, self.b)
        return (traj.end_mass - data).ravel()


@pytest.mark.slow
def test_sensitivity_jacobians_recover_the_parameters_and_the_covariance():
    # The Jacobian from sensitivities integrated beside the state (under the error
    # control) against forward mode through the solve, on a smooth motion where
    # both resolve it: the same optimum and the same Gauss-Newton covariance.
    start = _scene(EA=1.4e3, alpha=0.03)
    kw = dict(ts=TS, sigma=1e-4)
    fwd = js.least_squares(start, js.Misfit(_data()), ["alpha", "EA"], **kw)
    sens = js.least_squares(
        start, js.Misfit(_data()), ["alpha", "EA"], adjoint="sensitivity", **kw
    )
    assert sens.converged, sens.message
    assert sens.values["alpha"] == pytest.approx(TRUTH["alpha"], rel=1e-4)
    assert sens.values["EA"] == pytest.approx(TRUTH["EA"], rel=1e-4)
    np.testing.assert_allclose(sens.cov, fwd.cov, rtol=1e-4)


@pytest.mark.slow
def test_gauss_newton_jacobians_agree_between_forward_mode_and_sensitivities():
    # gauss_newton's Jacobian in the parameters' own units, both ways, against
    # central differences of tight solves (rtol 1e-11), column by column.
    sc = _scene()
    misfit = js.Misfit(_data() + 1e-4)
    kw = dict(ts=TS, sigma=1e-4)
    fwd = js.gauss_newton(sc, misfit, ["alpha", "EA"], **kw)
    sens = js.gauss_newton(sc, misfit, ["alpha", "EA"], adjoint="sensitivity", **kw)

    def residuals(alpha, EA):
        s = _scene(alpha=alpha, EA=EA)
        traj = js.simulate(s, "rodas5p", rtol=1e-11, atol=1e-11, ts=TS)
        return np.asarray(misfit(traj, s)).ravel()

    a, e = TRUTH["alpha"], TRUTH["EA"]
    fd = np.stack(
        [
            (residuals(1.0001 * a, e) - residuals(0.9999 * a, e)) / (2e-4 * a),
            (residuals(a, 1.0001 * e) - residuals(a, 0.9999 * e)) / (2e-4 * e),
        ],
        axis=1,
    )
    for J in (fwd["J"], sens["J"]):
        err = np.linalg.norm(J - fd, axis=0) / np.linalg.norm(fd, axis=0)
        assert np.all(err < 1e-4), err


@pytest.mark.slow
def test_an_iteration_limit_is_reported_not_raised():
    start = _scene(EA=1.4e3, alpha=0.03)
    res = js.least_squares(
        start, js.Misfit(_data()), ["alpha", "EA"], ts=TS, max_iters=1
    )
    assert not res.converged
    assert "max_iters" in res.message


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(params=["alfa"]), "alfa"),
        (dict(residual_fn=lambda traj, s: jnp.sum(traj.end_mass)), "residual_fn"),
        pytest.param(  # a solve to find the NaN: a compilation of its own
            dict(residual_fn=lambda traj, s: traj.end_mass.ravel() * jnp.nan),
            "NaN",
            marks=pytest.mark.slow,
        ),
        (dict(bounds={"EA": (2e3, 3e3)}), "bounds"),
        (dict(bounds={"mu": (0.1, 3.0)}), "bounds"),
        (dict(scene="not a scene"), "scene"),
        (dict(params=[]), "params"),
        (dict(rtol=-1.0), "rtol"),
        (dict(max_iters=0), "max_iters"),
        (dict(adjoint="reverse"), "adjoint"),
        (
            dict(
                scene=js.pendulum.string_pendulum("natural", k=4, t1=0.3),
                adjoint="sensitivity",
            ),
            "NaturalTangentString",
        ),
    ],
)
def test_bad_input_names_the_argument(kwargs, match):
    args = dict(
        scene=_scene(),
        residual_fn=js.Misfit(_data()),
        params=["alpha", "EA"],
        ts=TS,
    )
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        js.least_squares(**args)


def test_experiments_of_one_structure_are_solved_in_one_vmap():
    from jaxstring import SolveConfig
    from jaxstring._least_squares import _Problem, _stack_scenes
    from jaxstring._parameters import resolve

    a, b = _scene(), _scene(3 * np.pi / 8)
    assert _stack_scenes((a, b)) is not None
    # Another element count is another structure: solved one after the other.
    k8 = js.pendulum.string_pendulum("displacement", k=8, t1=0.3)
    assert _stack_scenes((a, k8)) is None
    getters = tuple(resolve(a, p) for p in ("alpha", "EA"))
    residual = _TwoData(jnp.asarray(_data()), jnp.asarray(_data(3 * np.pi / 8)))
    config = SolveConfig(solver="kvaerno5", rtol=1e-10, atol=1e-10)
    theta = [jnp.log(0.06), jnp.log(1.2e3)]
    args = (getters, (True, True), residual, config, TS)
    residuals = eqx.filter_jit(lambda problem, th: problem.residuals(th))
    looped = residuals(_Problem((a, b), None, *args), theta)
    batched = residuals(_Problem((a, b), _stack_scenes((a, b)), *args), theta)
    assert looped.shape == batched.shape == (2 * TS.size * 2,)
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-9)


# --------------------------------------------------------------------------------------
# Experiments over worker processes


def _two_structures():
    """Two experiments of different structures (4 and 5 elements), so that one
    process also solves them one after the other, as the workers do."""
    k5 = lambda **kw: js.pendulum.string_pendulum(
        "displacement", k=5, t1=0.3, theta0=3 * np.pi / 8, **(TRUTH | kw)
    )
    truth = js.simulate(k5(), "rodas5p", rtol=1e-11, atol=1e-11, ts=TS)
    residual = _TwoData(jnp.asarray(_data()), jnp.asarray(truth.end_mass))
    starts = [_scene(EA=1.4e3, alpha=0.03), k5(EA=1.4e3, alpha=0.03)]
    return starts, residual


def _same_fit(one, two):
    assert two.converged, two.message
    # The same steps, but for the last ones, taken at a cost at the rounding level
    # of the data (1e-14): rounding decides whether the iteration stops a step or
    # two earlier (workers compile with whole-loop kernels, another rounding; 22
    # against 20 iterations on an AMD EPYC, 1 apart on an Intel Xeon).
    assert abs(two.iterations - one.iterations) <= 3
    for name in ("alpha", "EA"):
        assert two.values[name] == pytest.approx(one.values[name], rel=1e-10)
        assert two.std[name] == pytest.approx(one.std[name], rel=1e-8)
    assert two.cost == pytest.approx(one.cost, rel=1e-6, abs=1e-20)


def test_a_worker_process_gives_the_one_process_fit(one_process_fit):
    start = _scene(EA=1.4e3, alpha=0.03)
    two = js.least_squares(
        start, js.Misfit(_data()), ["alpha", "EA"], ts=TS, processes=2
    )
    assert one_process_fit.processes == 1 and two.processes == 2
    _same_fit(one_process_fit, two)
    assert two.values["alpha"] == pytest.approx(TRUTH["alpha"], rel=1e-4)


@pytest.mark.slow
def test_two_worker_processes_give_the_one_process_fit_of_two_experiments():
    starts, residual = _two_structures()
    fit = functools.partial(js.least_squares, starts, residual, ["alpha", "EA"], ts=TS)
    one, two = fit(processes=1), fit(processes=2)
    assert one.processes == 1 and two.processes == 2
    _same_fit(one, two)
    for name in ("alpha", "EA"):
        assert two.values[name] == pytest.approx(TRUTH[name], rel=1e-4)
    assert float(two.scenes[1].model.EA) == pytest.approx(two.values["EA"])
    # "auto": one worker per experiment, up to the cores of a CPU host.
    auto = fit()
    assert auto.processes == (2 if host_cores() >= 2 else 1)
    _same_fit(one, auto)


@pytest.mark.parametrize(
    "kw, parts",
    [
        (dict(processes=0), ["`processes`", "0", ">= 1"]),
        (dict(processes=1.5), ["`processes`", "1.5"]),
        (dict(executor="pool"), ["`executor`", "'pool'", "Executor"]),
    ],
)
def test_bad_worker_settings_are_refused_by_name(kw, parts):
    with pytest.raises(ValueError) as info:
        js.least_squares(_scene(), js.Misfit(_data()), ["alpha"], ts=TS, **kw)
    for part in parts:
        assert part in str(info.value)


def test_experiments_go_to_the_cores_wherever_their_solves_run_on_a_cpu(monkeypatch):
    # On a GPU host a single solve runs on the host CPU ("auto"), so several
    # experiments go to worker processes on its cores, as on a CPU host; placed on
    # the GPU they stay in this process.
    from jaxstring._least_squares import _workers

    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    three = [_scene()] * 3
    auto = js.SolveConfig()
    assert _workers("auto", None, three, auto) == min(host_cores(), 3)
    assert _workers("auto", None, three[:1], auto) == 1
    assert _workers("auto", None, three, auto.replace(device="default")) == 1
    assert not auto.replace(device="default").on_cpu()
    assert _workers(2, None, three, auto) == 2
    assert _workers("auto", object(), three, auto) == 0


def _kill_experiment():
    """A pool whose worker dies on every evaluation of the experiment with 5
    elements (its state has 5 rows)."""
    return KillingPool(lambda leaves: any(np.shape(x)[:1] == (5,) for x in leaves[1:]))


@pytest.mark.slow
def test_an_experiment_whose_worker_dies_is_reported_not_raised():
    starts, residual = _two_structures()
    with _kill_experiment() as executor:
        res = js.least_squares(
            starts, residual, ["alpha", "EA"], ts=TS, executor=executor
        )
    assert res.processes == 0
    assert not res.converged
    assert "evaluation of experiment 1 failed" in res.message
