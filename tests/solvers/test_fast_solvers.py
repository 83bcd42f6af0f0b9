"""Fast stiff integration: Rodas5P, theta and Newmark, the stage Newton iteration's
refreshes and the model's own Jacobian in the solvers (their linear algebra:
test_linalg.py)."""

import functools
import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _fit, _linalg
from jaxstring._solvers.esdirk import ESDIRK
from jaxstring._solvers.fixed_step import Newmark, ThetaMethod
from jaxstring._solvers.rosenbrock import Rodas5P
from jaxstring._solvers.stage_newton import StageNewton
from jaxstring.pendulum.effects import AbstractStringLoad, Loads
from jaxstring.pendulum.models import DisplacementString

from ..helpers import (
    assert_grad_matches_central_differences,
    dense_jacobian,
    fitted_order,
    string_vf,
)


# ---------------------------------------------------------------------------
# Problems with known solutions
# ---------------------------------------------------------------------------

_W, _C = 3.0, 0.4  # free damped oscillator q'' = -w^2 q - c q'


def _oscillator(t, y, args):
    del t, args
    q, v = y[:, :1], y[:, 1:]
    return jnp.concatenate([v, -(_W**2) * q - _C * v], axis=1)


def _oscillator_exact(t):
    wd = math.sqrt(_W**2 - _C**2 / 4)
    e = math.exp(-_C * t / 2)
    q = e * (math.cos(wd * t) + _C / (2 * wd) * math.sin(wd * t))
    v = -e * (_W**2 / wd) * math.sin(wd * t)
    return np.array([[q, v]])


def _fixed_errors(solver, vf, y0, exact, hs, t1=2.0):
    errs = []
    for h in hs:
        sol = dfx.diffeqsolve(dfx.ODETerm(vf), solver, 0.0, t1, h, y0)
        assert sol.result == dfx.RESULTS.successful
        errs.append(float(np.max(np.abs(np.asarray(sol.ys[-1]) - exact(t1)))))
    return errs


@pytest.mark.parametrize(
    "solver, order",
    [
        (ThetaMethod(theta=0.5), 2.0),
        (ThetaMethod(theta=1.0), 1.0),
        (ThetaMethod(theta=0.75), 1.0),
        (Newmark(gamma=0.5, beta=0.25), 2.0),
    ],
)
def test_fixed_step_order_on_damped_oscillator(solver, order):
    hs = (0.02, 0.01, 0.005)
    y0 = jnp.array([[1.0, 0.0]])
    errs = _fixed_errors(solver, _oscillator, y0, _oscillator_exact, hs)
    slope = fitted_order(hs, errs)
    assert abs(slope - order) < 0.1, (slope, errs)


def test_rodas5p_order_five_on_nonlinear_problem():
    # Logistic equation u' = u (1 - u), u(0) = 0.1 (exact solution). (On linear
    # problems Rodas5P's stability function is more accurate than order 5, so a
    # linear test problem would overstate the order.)
    hs = (0.2, 0.1, 0.05, 0.025)

    def vf(t, y, args):
        del t, args
        return y * (1 - y)

    def exact(t):
        return np.array([[1 / (1 + 9 * math.exp(-t))]])

    errs = _fixed_errors(Rodas5P(), vf, jnp.array([[0.1]]), exact, hs, t1=4.0)
    slope = fitted_order(hs, errs)
    assert 4.6 < slope < 5.4, (slope, errs)


@pytest.mark.parametrize(
    "solver", [Rodas5P(), ESDIRK(method="kvaerno5", rtol=1e-7, atol=1e-7)]
)
def test_stiff_prothero_robinson(solver):
    # y' = lam (y - g) + g', exact y = g = sin t, lam = -1e6: the step size must be
    # set by the smooth solution, not by lam (an explicit method would need ~1e6
    # steps), and the steps must stay accurate (stiff accuracy).
    lam = -1e6

    def vf(t, y, args):
        del args
        return lam * (y - jnp.sin(t)) + jnp.cos(t)

    sol = dfx.diffeqsolve(
        dfx.ODETerm(vf),
        solver,
        0.0,
        3.0,
        1e-3,
        jnp.zeros((1, 1)),
        stepsize_controller=dfx.PIDController(rtol=1e-7, atol=1e-7),
        saveat=dfx.SaveAt(steps=True),
    )
    n = int(sol.stats["num_accepted_steps"])
    ts = np.asarray(sol.ts[:n])
    err = np.max(np.abs(np.asarray(sol.ys[:n, 0, 0]) - np.sin(ts)))
    assert err < 1e-6, err
    assert n < 50, n


def test_rodas5p_dense_output_order():
    # Between steps the interpolant is of order 4 (local error O(h^5)) on a smooth
    # problem: logistic equation, read half-way through a step.
    def vf(t, y, args):
        del t, args
        return y * (1 - y)

    hs = (0.2, 0.1, 0.05)
    errs = []
    for h in hs:
        t = 1.0 + h / 2
        sol = dfx.diffeqsolve(
            dfx.ODETerm(vf),
            Rodas5P(),
            0.0,
            2.0,
            h,
            jnp.array([[0.1]]),
            saveat=dfx.SaveAt(ts=jnp.array([t])),
        )
        errs.append(abs(float(sol.ys[0, 0, 0]) - 1 / (1 + 9 * math.exp(-t))))
    slope = fitted_order(hs, errs)
    assert 4.5 < slope < 5.6, (slope, errs)


# ---------------------------------------------------------------------------
# String pendulum: agreement with a tight reference, fixed-step paper setting
# ---------------------------------------------------------------------------


@functools.cache
def _reference(formulation, k, EA, t1):
    scene = js.string_pendulum(formulation, k=k, EA=EA, t1=t1)
    ts = jnp.linspace(0.0, t1, 5)
    return js.simulate(scene, "kvaerno5", rtol=1e-11, atol=1e-11, ts=ts)


def _err(traj, ref):
    return float(np.max(np.linalg.norm(traj.end_mass - ref.end_mass, axis=1)))


# Slow: in the default run Rodas5P is the tight reference that BDF
# (test_bdf) and the written-out Kvaerno5 (test_esdirk) agree with on the string.
@pytest.mark.slow
@pytest.mark.parametrize("formulation", ("displacement", "angle"))
def test_rodas5p_agrees_with_kvaerno5_reference(formulation):
    ref = _reference(formulation, 6, 1e4, 0.4)
    scene = js.string_pendulum(formulation, k=6, EA=1e4, t1=0.4)
    traj = js.simulate(scene, "rodas5p", rtol=1e-8, atol=1e-8, ts=ref.ts)
    assert traj.ok, traj.status
    assert _err(traj, ref) < 1e-6, _err(traj, ref)


@pytest.mark.parametrize("solver", ("theta", "newmark"))
def test_fixed_step_solvers_second_order_on_string(solver):
    ref = _reference("displacement", 6, 1e4, 0.4)
    scene = js.string_pendulum("displacement", k=6, EA=1e4, t1=0.4)
    dts = (0.004, 0.002, 0.001)
    errs = []
    for dt in dts:
        traj = js.simulate(scene, solver, dt0=dt, rtol=1e-10, atol=1e-10, ts=ref.ts)
        assert traj.ok, traj.status
        assert int(traj.stats["num_accepted_steps"]) == round(0.4 / dt)
        errs.append(_err(traj, ref))
    slope = fitted_order(dts, errs)
    assert 1.8 < slope < 2.3, (slope, errs)


@pytest.mark.slow
@pytest.mark.parametrize("solver", ("theta", "newmark"))
def test_fixed_step_paper_setting_runs(solver):
    # The paper's setting: dt = 0.005, 400 steps over 2 s, EA = 1e6. Measured
    # end-mass error against Rodas5P at 1e-9: 5.2e-3 m (implicit Euler: 0.24 m).
    scene = js.string_pendulum("displacement", k=10, EA=1e6, t1=2.0)
    ts = jnp.linspace(0.0, 2.0, 9)
    ref = js.simulate(scene, "rodas5p", rtol=1e-9, atol=1e-9, ts=ts)
    traj = js.simulate(scene, solver, dt0=0.005, rtol=1e-7, atol=1e-7, ts=ts)
    assert traj.ok, traj.status
    assert int(traj.stats["num_accepted_steps"]) == 400
    assert _err(traj, ref) < 2e-2, _err(traj, ref)


def _kvaerno5(scene, ts, cls=dfx.Kvaerno5, **newton_kw):
    """A successful solve at rtol = atol = 1e-6 by Kvaerno5 `cls` (diffrax's, one
    Jacobian per step, unless given) with a StageNewton of `newton_kw`."""
    rf = StageNewton(rtol=1e-6, atol=1e-6, **newton_kw)
    solver = cls(root_finder=rf, root_find_max_steps=10)
    traj = js.simulate(scene, solver, rtol=1e-6, atol=1e-6, ts=ts)
    assert traj.ok, traj.status
    return traj


# Slow: a count of Newton attempts (an option's effect on cost, not on the
# answer); the refreshed Newton's solution is checked by the tight-reference tests.
@pytest.mark.slow
def test_newton_refresh_removes_displacement_rejections():
    # Displacement variables at EA = 1e9: a Jacobian frozen at the stage predictor
    # contracts at a rate near 1 (the stiff axial force turns with the string), so
    # nearly every larger step failed in Newton. Refreshing the Jacobian at the
    # iterate removes most attempts, at the same answer.
    scene = js.string_pendulum("displacement", k=8, EA=1e9, t1=0.2)
    ts = jnp.linspace(0.0, 0.2, 3)
    runs = {r: _kvaerno5(scene, ts, refresh=r) for r in (False, True)}
    attempts = {r: int(t.stats["num_steps"]) for r, t in runs.items()}
    assert attempts[True] * 5 < attempts[False], attempts
    assert _err(runs[True], runs[False]) < 1e-5


@pytest.mark.slow
def test_refresh_before_predicted_divergence():
    # A stale Jacobian on the EA = 1e9 string often contracts at a rate below
    # `refresh_rate` that is still too slow to converge within `max_iters`;
    # declaring divergence on that prediction (the old rule, with at most 3
    # Jacobians) failed the step, refreshing first lets it converge: about 2.8x
    # fewer step attempts (362 -> 130 here; k = 40, 2 s: 21k -> 8.9k accepted steps,
    # docs, numerics), the same answer.
    scene = js.string_pendulum("displacement", k=8, EA=1e9, t1=0.2)
    ts = jnp.linspace(0.0, 0.2, 3)
    runs = {
        "old": _kvaerno5(scene, ts, refresh_when_hopeless=False, max_jacobians=3),
        "new": _kvaerno5(scene, ts),
    }
    attempts = {n: int(t.stats["num_steps"]) for n, t in runs.items()}
    assert 2 * attempts["new"] < attempts["old"], attempts
    ref = js.simulate(scene, "rodas5p", rtol=1e-11, atol=1e-11, ts=ts)
    assert _err(runs["new"], ref) < 1e-5
    assert _err(runs["new"], runs["old"]) < 1e-5


@pytest.mark.slow
def test_stage_jacobians_cut_kvaerno5_attempts():
    # diffrax's Kvaerno5 takes one Jacobian per step and starts every later stage
    # from it; on the displacement string at EA = 1e9 it is stale by then and the
    # step size is held down by Newton failures. jaxstring's Kvaerno5 takes it at
    # each stage's predictor: fewer attempts, the same answer (here 130 -> 30;
    # k = 40, 2 s: 9757 -> 3797 attempts; docs, numerics).
    scene = js.string_pendulum("displacement", k=8, EA=1e9, t1=0.2)
    ts = jnp.linspace(0.0, 0.2, 3)
    runs = {
        "step": _kvaerno5(scene, ts, cls=dfx.Kvaerno5),
        "stage": _kvaerno5(scene, ts, cls=js.Kvaerno5),
    }
    attempts = {n: int(t.stats["num_steps"]) for n, t in runs.items()}
    assert 3 * attempts["stage"] < attempts["step"], attempts
    ref = js.simulate(scene, "rodas5p", rtol=1e-11, atol=1e-11, ts=ts)
    assert _err(runs["stage"], ref) < 1e-5


@pytest.mark.parametrize("structure", ("dense", "banded", "reduced"))
def test_identity_factor_of_the_explicit_stage(structure):
    # The explicit first stage of an ESDIRK gets the identity factor (no Jacobian):
    # it must solve as the identity, with the structure of a real factorisation.
    from jaxstring._solvers.stage_newton import _identity_like

    fn, y, scene = string_vf("displacement", 16)
    width = None if structure == "dense" else 1
    so = 2 if structure == "reduced" else 0
    jac = lambda: _linalg.jacobian(lambda u: fn(u, scene), y, width, second_order=so)
    real = jax.eval_shape(lambda: _linalg.factor(jac().scale_shift(1.0, -1e-3)))
    ident = _identity_like(real)
    assert jax.tree.structure(ident) == jax.tree.structure(real)
    rhs = jnp.asarray(np.random.default_rng(2).standard_normal(y.shape))
    assert np.array_equal(np.asarray(ident.solve(rhs)), np.asarray(rhs))


@pytest.mark.parametrize(
    "formulation, dim",
    [
        ("displacement", 2),
        ("displacement", 3),
        ("natural", 2),
        ("natural", 3),
        ("angle", 2),
    ],
)
def test_declared_band_equals_the_detected_band(formulation, dim):
    # The string models declare their Jacobian's node bandwidth, so that implicit
    # solvers skip the trace-time probe (a compilation per relation):
    # the declaration must be what probing finds, with every string effect on.
    from jaxstring._scene import scene_vector_field

    scene = js.string_pendulum(
        formulation=formulation,
        k=12,
        dim=dim,
        effects=("gravity", "kelvin_voigt", "slack"),
    )
    vf = lambda y, a: scene_vector_field(0.3, y, a)
    declared = _linalg.declared_width(vf, scene.y0, scene)
    assert declared == 1
    assert _linalg.detect_width(vf, scene.y0, scene) == declared
    # Not for a state of another shape (e.g. Newmark's accelerations).
    assert _linalg.declared_width(vf, scene.y0[:, :2], scene) is None


@pytest.mark.parametrize("method", ["lms", "aceam", "exact"])
def test_tether_structure_is_what_probing_finds(method):
    # The spring tether declares band 1; ACEAM's and the exact tensions are solved
    # over the whole chain, so those declare a dense Jacobian: implicit solves of a
    # tether skip the probe. The declarations must be what probing finds, with
    # drag in a current and a moving winch.
    scene = js.tether.tether_winch(method=method, N=11, t1=1.0)
    vf = lambda y, s: s.vector_field(0.3, y)
    detected = _linalg.detect_width(vf, scene.y0, scene)
    if method == "lms":
        assert _linalg.declared_width(vf, scene.y0, scene) == 1 == detected
    else:
        assert scene.structure.dense and detected is None
        assert _linalg.choose_structure(vf, scene.y0, scene) is None


class ZeroLoad(AbstractStringLoad):
    """A load jaxstring's string does not know (and that adds nothing): the model
    then gives no Jacobian of its own and the solvers probe with JVPs."""

    def forces(self, t, kin, env):
        return Loads(jnp.zeros_like(kin.positions), jnp.zeros_like(kin.positions[-1]))


@pytest.mark.parametrize(
    "solver",
    (
        pytest.param("bdf", marks=pytest.mark.slow),
        pytest.param("rodas5p", marks=pytest.mark.slow),
        pytest.param("kvaerno5", marks=pytest.mark.slow),
    ),
)
def test_solvers_with_the_model_jacobian_equal_the_probed_one(solver, monkeypatch):
    # k = 14 (56 states) is on the banded path (small systems go dense). The same
    # scene solved with the model's Jacobian and, through an unknown (zero) load,
    # with the coloured-JVP one: same steps, same answer, and both at the accuracy
    # of a tight Kvaerno5 reference.
    calls = []
    own = DisplacementString.vf_jacobian

    def spy(self, t, y, effects, env):
        jac = own(self, t, y, effects, env)
        calls.append(jac is not None)
        return jac

    monkeypatch.setattr(DisplacementString, "vf_jacobian", spy)
    ref = _reference("displacement", 14, 1e4, 0.3)
    # A solver's step is traced once per structure (`traced_once`) and kept: a
    # Kvaerno5 step of this structure, traced for the reference or another test,
    # would be reused without calling the spy. Trace every solve here afresh.
    jax.clear_caches()
    scene = js.string_pendulum("displacement", k=14, EA=1e4, t1=0.3)
    probed = eqx.tree_at(lambda s: s.effects, scene, scene.effects + (ZeroLoad(),))
    # The reference's save times and the midpoints between them.
    kw = dict(rtol=1e-8, atol=1e-8, ts=jnp.linspace(0.0, 0.3, 9))
    calls.clear()
    a = js.simulate(scene, solver, **kw)
    assert any(calls)  # traced with the model's own Jacobian
    calls.clear()
    b = js.simulate(probed, solver, **kw)
    # under the unknown load the model declares no Jacobian of its own
    assert not scene.structure.jacobian or not probed.structure.jacobian
    assert not any(calls)
    assert a.ok and b.ok
    assert int(a.stats["num_steps"]) == int(b.stats["num_steps"])
    diff = float(np.max(np.abs(np.asarray(a.ys) - np.asarray(b.ys))))
    assert diff < 1e-9, diff
    err = float(np.max(np.linalg.norm(a.end_mass[::2] - ref.end_mass, axis=1)))
    assert err < 1e-6, err


@pytest.mark.slow
def test_rodas5p_gradient_through_the_model_jacobian():
    # Rodas5P's stages use J itself, so a gradient of the solution differentiates
    # the model's Jacobian (dN/d eps and dN/d eps_dot of the laws, to second
    # order): forward-mode gradients against central differences, k = 12 (banded).
    scene = js.string_pendulum(k=12, EA=1e3, alpha=0.02, t1=0.2)
    config = _fit.SolveConfig(solver="rodas5p", rtol=1e-10, atol=1e-10, n_save=5)
    end = lambda traj, s: jnp.sum(traj.obs["positions"][:, -1, :] ** 2)
    _, grad = _fit.value_and_grad(
        scene,
        end,
        ["alpha", "EA"],
        adjoint="forward",
        solver="rodas5p",
        rtol=1e-10,
        atol=1e-10,
        n_save=5,
    )
    assert_grad_matches_central_differences(
        lambda s: end(_fit.solve(s, config), s), scene, grad
    )


def test_stage_model_jacobian_only_for_the_scenes_own_relation():
    # Kvaerno's stage relation g(f) = f - vf(t, y + a f dt): with the scene's vector
    # field its Jacobian is I - a dt J from the model; with another vector field and
    # the scene as args (vf is opaque to the root finder) the matrix is NaN, so the
    # Newton iteration fails instead of using the wrong Jacobian.
    from jaxstring._solvers.stage_newton import _stage_model_jacobian

    scene = js.string_pendulum(k=14, EA=1e4)
    rng = np.random.default_rng(7)
    y = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    f = jnp.asarray(rng.standard_normal(y.shape))
    a, dt, t = 0.25, 1e-3, 0.1
    own = lambda t, u, s: s.vector_field(t, u)
    prod = lambda f, c: f * c
    args = (1, jnp.asarray(a), own, prod, jnp.asarray(t), y, scene, jnp.asarray(dt))
    jac = _stage_model_jacobian(f, args)
    J = dense_jacobian(scene, y + a * dt * f, t)
    expect = np.eye(J.shape[0]) - a * dt * J
    assert np.max(np.abs(np.asarray(jac.to_dense()) - expect)) < 1e-12 * np.max(
        np.abs(expect)
    )
    other = lambda t, u, s: 2.0 * s.vector_field(t, u)
    bad = _stage_model_jacobian(f, args[:2] + (other,) + args[3:])
    assert np.all(np.isnan(np.asarray(bad.to_dense())[:, 4:]))
    # Not a stage relation, or a model without its own Jacobian: None.
    assert _stage_model_jacobian(f, args[:7]) is None
    angle = js.string_pendulum("angle", k=14)
    assert (
        _stage_model_jacobian(angle.y0, args[:5] + (angle.y0, angle, args[7])) is None
    )


def test_theta_method_model_jacobian_only_for_the_scenes_own_vector_field():
    # The theta method's residual r(dy) = dy - h (theta f(t1, y0 + dy) + ...): with
    # the scene's vector field its Jacobian is I - h theta J from the model; with
    # another vector field and the scene as args the matrix is NaN (the Newton
    # iteration fails instead of using the wrong Jacobian); a model without its
    # own Jacobian gives None (probed with JVPs).
    import diffrax as dfx

    from jaxstring._solvers.fixed_step import _ThetaResidual

    scene = js.string_pendulum(k=14, EA=1e4)
    rng = np.random.default_rng(11)
    y0 = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    dy = 1e-3 * jnp.asarray(rng.standard_normal(y0.shape))
    h, t1, theta = jnp.asarray(2e-3), jnp.asarray(0.1), 0.5
    term = dfx.ODETerm(lambda t, u, s: s.vector_field(t, u))
    residual = _ThetaResidual(theta)
    f0 = scene.vector_field(t1 - h, y0)
    jac = residual.model_jacobian(dy, (t1, y0, h, f0, term, scene))
    J = dense_jacobian(scene, y0 + dy, 0.1)
    expect = np.eye(J.shape[0]) - float(h) * theta * J
    assert np.max(np.abs(np.asarray(jac.to_dense()) - expect)) < 1e-12 * np.max(
        np.abs(expect)
    )
    # the residual's own derivative, by autodiff, is the same matrix
    auto = jax.jacfwd(
        lambda d: residual(d.reshape(dy.shape), (t1, y0, h, f0, term, scene))
    )(dy.ravel())
    assert np.max(np.abs(np.asarray(auto).reshape(expect.shape) - expect)) < 1e-10
    other = dfx.ODETerm(lambda t, u, s: 2.0 * s.vector_field(t, u))
    bad = residual.model_jacobian(dy, (t1, y0, h, f0, other, scene))
    assert np.all(np.isnan(np.asarray(bad.to_dense())[:, 4:]))
    angle = js.string_pendulum("angle", k=14)
    a = (t1, angle.y0, h, None, term, angle)
    assert residual.model_jacobian(jnp.zeros_like(angle.y0), a) is None


@pytest.mark.parametrize("solver", ("implicit_euler_fixed", "theta"))
def test_fixed_step_solvers_with_the_model_jacobian_equal_the_probed_one(solver):
    # The same fixed-step solve (k = 14, banded) with the model's Jacobian and,
    # through an unknown (zero) load, with the coloured-JVP one: both solve each
    # step's equation to the Newton test, so the trajectories agree far inside
    # the Newton tolerance, and both converge to a tight Kvaerno5 reference at
    # the method's order (halving the step: implicit Euler's error halves, the
    # trapezoidal rule's quarters).
    scene = js.string_pendulum("displacement", k=14, EA=1e4, t1=0.3)
    probed = eqx.tree_at(lambda s: s.effects, scene, scene.effects + (ZeroLoad(),))
    assert scene.structure.jacobian and not probed.structure.jacobian
    ts = jnp.linspace(0.0, 0.3, 9)
    a = js.simulate(scene, solver, dt0=1e-3, ts=ts)
    b = js.simulate(probed, solver, dt0=1e-3, ts=ts)
    half = js.simulate(scene, solver, dt0=5e-4, ts=ts)
    assert a.ok and b.ok and half.ok
    diff = float(np.max(np.abs(np.asarray(a.ys) - np.asarray(b.ys))))
    assert diff < 1e-10, diff
    ref = _reference("displacement", 14, 1e4, 0.3)
    err, err_half = (
        float(np.max(np.linalg.norm(t.end_mass[::2] - ref.end_mass, axis=1)))
        for t in (a, half)
    )
    order = 1 if solver == "implicit_euler_fixed" else 2
    assert 0.9 * 2**order < err / err_half < 1.1 * 2**order, (err, err_half)
