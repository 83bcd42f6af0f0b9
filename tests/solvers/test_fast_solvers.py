"""Fast stiff integration: banded Newton matrices, Rodas5P, theta and Newmark."""

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
    FORMULATIONS,
    assert_grad_matches_central_differences,
    fitted_order,
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
# Banded linear algebra on string Jacobians
# ---------------------------------------------------------------------------


def _dense_jacobian(scene, y, t=0.0):
    """The vector field's Jacobian at y, dense `(n b, n b)`, by compiled jacfwd."""
    n, b = y.shape
    f = lambda v: scene.vector_field(t, v.reshape(n, b)).reshape(-1)
    return np.asarray(jax.jit(jax.jacfwd(f))(y.reshape(-1)))


def _string_vf(formulation, k):
    scene = js.string_pendulum(formulation, k=k, EA=1e6, theta0=1.0)
    y = scene.y0 + 0.01 * jax.random.normal(jax.random.PRNGKey(0), scene.y0.shape)
    return (lambda u, s: s.vector_field(0.0, u)), y, scene


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_string_jacobian_is_block_tridiagonal_and_detected(formulation):
    fn, y, scene = _string_vf(formulation, 13)
    assert _linalg.detect_width(fn, y, scene) == 1
    # The dense Jacobian's nonzeros lie within one node of the diagonal...
    n, b = y.shape
    J = np.asarray(_dense_jacobian(scene, y, 0.0))
    rows, cols = np.nonzero(J)
    assert np.max(np.abs(rows // b - cols // b)) == 1
    # ... and 3 b coloured JVPs reproduce it exactly.
    bt = jax.jit(
        lambda u, s: _linalg.block_tridiagonal_jacobian(
            lambda v: fn(v, s), u, 1
        ).to_dense()
    )(y, scene)
    assert np.max(np.abs(np.asarray(bt) - J)) <= 1e-14 * np.max(np.abs(J))


def test_detect_width_rejects_global_coupling():
    # Every row depends on every node: no band, dense path.
    def fn(u, a):
        return u * jnp.sum(u) * a

    assert _linalg.detect_width(fn, jnp.ones((20, 4)), jnp.array(2.0)) is None


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize(
    "k, c", [(13, 1e-3), pytest.param(27, 1e-4, marks=pytest.mark.slow)]
)
def test_banded_newton_solve_equals_dense(formulation, k, c):
    # Newton matrices I - c J of strings are badly scaled (condition 1e9 ... 1e11:
    # metres next to metres per second), so two backward-stable solvers may differ
    # by up to cond * eps in the forward sense. Block cyclic reduction is backward
    # stable (normwise backward error at round-off), and with one step of
    # iterative refinement it equals the (refined) dense LU solve to 5e-12, seven
    # orders below cond * eps. (Measured: at most 1.2e-12, displacement, k = 27,
    # c = 1e-4, cond 1.3e11, with `factor` compiled as one XLA program as in the
    # solvers; 5.6e-13 when it ran op by op.)
    fn, y, scene = _string_vf(formulation, k)
    n, b = y.shape
    J = _dense_jacobian(scene, y)
    M = np.eye(n * b) - c * J
    rhs = np.random.default_rng(0).standard_normal((n, b))
    dense = np.linalg.solve(M, rhs.reshape(-1))
    # The dense LU solve, refined with residuals in extended precision: accurate to
    # well below 1e-12 (its own forward error is up to cond * eps).
    for _ in range(2):
        res = M.astype(np.longdouble) @ dense.astype(np.longdouble) - rhs.reshape(-1)
        dense = dense - np.linalg.solve(M, res.astype(np.float64))

    @jax.jit
    def banded(u, s, r):
        # the solve and one step of iterative refinement
        Mb = _linalg.block_tridiagonal_jacobian(lambda v: fn(v, s), u, 1)
        Mb = Mb.scale_shift(1.0, -c)
        fac = _linalg.factor(Mb)
        x = fac.solve(r)
        return x, x + fac.solve(r - Mb.matvec(x))

    x, refined = banded(y, scene, jnp.asarray(rhs))
    xf = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ xf - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(xf))
    )
    assert backward < 1e-15, backward
    forward = np.max(np.abs(xf - dense)) / np.max(np.abs(dense))
    assert forward < 1e-8, forward
    err = np.max(np.abs(np.asarray(refined).reshape(-1) - dense)) / np.max(
        np.abs(dense)
    )
    assert err < 5e-12, err


def test_block_inverse_pivots():
    a = np.random.default_rng(1).standard_normal((30, 6, 6))
    a[:, 0, 0] = 0.0  # a zero leading entry needs a row exchange
    err = np.max(np.abs(np.asarray(_linalg.small_inv(a)) - np.linalg.inv(a)))
    assert err < 1e-10, err


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

    fn, y, scene = _string_vf("displacement", 16)
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
    # solvers skip the trace-time probe (1.5-2 s of compilation per relation):
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


# ---------------------------------------------------------------------------
# The reduced Newton system of a second-order model (q, v rows, dq/dt = v)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("dim", (2, pytest.param(3, marks=pytest.mark.slow)))
@pytest.mark.parametrize(
    "a, b",
    [
        (1.0, -1e-3),
        pytest.param(1.0, -0.1, marks=pytest.mark.slow),
        pytest.param(100.0, -1.0, marks=pytest.mark.slow),
    ],
)
def test_second_order_factor_equals_dense_solve(dim, a, b):
    # a I + b J as BDF (a = 1, b = -c) and Rodas5P (a = 1 / (h gamma), b = -1) form
    # it: the velocity-reduced solve must be backward stable and equal the
    # (refined) dense one to within the conditioning of I - c A_v - c^2 A_x
    # (c^2 EA k^2 / (mu l^2) ~ 1e6 at c = 0.1: forward errors ~ 1e-10).
    scene = js.string_pendulum(
        k=11, dim=dim, EA=1e6, effects=("gravity", "kelvin_voigt", "slack")
    )
    rng = np.random.default_rng(dim)
    y = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    fn = lambda u: scene.vector_field(0.0, u)
    assert scene.structure.second_order == dim
    fac = lambda u: _linalg.factor(
        _linalg.jacobian(fn, u, 1, second_order=dim).scale_shift(a, b)
    )
    shape = jax.eval_shape(fac, y)
    assert isinstance(shape, _linalg.SecondOrderFactor)
    assert shape.sfac.dinv_last.shape == (dim, dim)  # d x d blocks, not 2d x 2d
    n = y.size
    J = _dense_jacobian(scene, y)
    rhs = rng.standard_normal(y.shape)
    M = a * np.eye(n) + b * J
    dense = np.linalg.solve(M, rhs.reshape(-1))
    for _ in range(2):  # refined as in the banded test above
        res = M.astype(np.longdouble) @ dense.astype(np.longdouble) - rhs.reshape(-1)
        dense = dense - np.linalg.solve(M, res.astype(np.float64))
    x = jax.jit(lambda u, r: fac(u).solve(r))(y, jnp.asarray(rhs))
    x = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ x - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(x))
    )
    assert backward < 1e-15, backward
    assert np.max(np.abs(x - dense)) / np.max(np.abs(dense)) < 1e-9


def test_declared_second_order_matches_the_jacobian():
    # DisplacementString declares rows (r, r') with dr/dt = r' exactly: the q rows
    # of its Jacobian are [0, I] and touch no other node, with every effect on.
    scene = js.string_pendulum(k=7, dim=2, effects=("gravity", "kelvin_voigt", "slack"))
    y = scene.y0 + 0.01
    n, b = y.shape
    J = _dense_jacobian(scene, y, 0.3).reshape(n, b, n, b)
    expect = np.zeros((n, 2, n, b))
    for i in range(n):
        expect[i, :, i, 2:] = np.eye(2)
    assert np.array_equal(J[:, :2], expect)
    # The natural variables declare nothing.
    nat = js.string_pendulum("angle", k=7)
    assert nat.structure.second_order == 0


def test_second_order_factor_refuses_a_wrong_structure():
    # A relation whose q rows couple nodes (not a I + b J of dq/dt = v) gives a NaN
    # factor, so the Newton iteration fails instead of converging to a wrong root.
    scene = js.string_pendulum(k=9)
    fn = lambda u: scene.vector_field(0.0, u) + 0.1 * jnp.roll(u, 1, axis=0)
    y = scene.y0 + 0.01

    @jax.jit
    def solve(u):
        mat = _linalg.jacobian(fn, u, 1, second_order=2).scale_shift(1, -0.1)
        return _linalg.factor(mat).solve(jnp.ones_like(u))

    assert np.all(np.isnan(np.asarray(solve(y))))


def test_closed_form_2x2_inverse():
    a = np.random.default_rng(3).standard_normal((50, 2, 2))
    err = np.max(np.abs(np.asarray(_linalg.small_inv(a)) - np.linalg.inv(a)))
    assert err < 1e-10, err


def test_ynnpack_fusions_are_off_in_jaxstrings_compilations():
    # simulate, fit and sweep compile with XLA:CPU's YNNPACK fusions off (they made
    # the coloured Jacobian 4-5x slower at k >= 320, experiments/results/
    # ynn_fusion.md), per compilation: a batched reduction compiled by `cpu_jit`
    # has no YNNPACK fusion, while plain `jax.jit` (the user's code) keeps XLA's
    # default.
    from jaxstring._jit import cpu_jit

    f = lambda x: jnp.sum(x * x[:, ::-1], axis=-1)
    x = jnp.ones((12, 640, 2))
    g = cpu_jit(f)
    assert np.array_equal(np.asarray(g(x)), np.asarray(f(x)))
    ours = g.lower_cpu(x).compile().as_text()
    assert "ynn_fusion" not in ours  # (the test's name is in the metadata)
    users = jax.jit(f).lower(x).compile().as_text()
    if "ynn_fusion" not in users:
        pytest.skip("this jaxlib makes no YNNPACK fusion here anyway")


# ---------------------------------------------------------------------------
# The displacement string's own element-wise Jacobian (`vf_jacobian`)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("dim", (2, 3))
@pytest.mark.parametrize(
    "effects",
    [("gravity", "kelvin_voigt"), ("gravity", "kelvin_voigt", "slack"), ()],
)
def test_model_jacobian_equals_autodiff(dim, effects):
    # Random states with stretched, compressed (slack: no force) and moving
    # elements: the written-out element derivatives equal jacfwd of the vector
    # field to rounding.
    scene = js.string_pendulum(k=9, dim=dim, EA=1e6, effects=effects)
    rng = np.random.default_rng(dim + len(effects))
    y = scene.y0 + 0.05 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    eps, _ = scene.model.strain(y)
    assert np.any(eps < 0) and np.any(eps > 0)
    jac = scene.model.vf_jacobian(0.0, y, scene.effects, scene.env)
    assert isinstance(jac, _linalg.SecondOrderJacobian)
    assert jac.p.diag.shape == (9, dim, dim)
    J = _dense_jacobian(scene, y)
    err = np.max(np.abs(np.asarray(jac.to_dense()) - J)) / np.max(np.abs(J))
    assert err < 1e-13, err
    # The matrix-vector product and the shift agree with the dense matrix.
    x = rng.standard_normal(y.shape)
    M = jac.scale_shift(2.0, -0.3)
    mv = np.asarray(M.matvec(jnp.asarray(x))).reshape(-1)
    dense = (2.0 * np.eye(J.shape[0]) - 0.3 * J) @ x.reshape(-1)
    assert np.max(np.abs(mv - dense)) / np.max(np.abs(dense)) < 1e-13


@pytest.mark.parametrize("a, b", [(1.0, -1e-3), (100.0, -1.0)])
def test_model_jacobian_factor_equals_dense_solve(a, b):
    # BDF's I - c J and Rodas5P's I / (h gamma) - J, factorised straight from the
    # model's v rows: backward stable, and equal to the dense solve.
    scene = js.string_pendulum(k=11, EA=1e6)
    rng = np.random.default_rng(5)
    y = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    fac = lambda u: _linalg.factor(
        scene.model.vf_jacobian(0.0, u, scene.effects, scene.env).scale_shift(a, b)
    )
    M = a * np.eye(y.size) + b * _dense_jacobian(scene, y)
    rhs = rng.standard_normal(y.shape)
    x = jax.jit(lambda u, r: fac(u).solve(r))(y, jnp.asarray(rhs))
    x = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ x - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(x))
    )
    assert backward < 1e-15, backward
    dense = np.linalg.solve(M, rhs.reshape(-1))
    assert np.max(np.abs(x - dense)) / np.max(np.abs(dense)) < 1e-8


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
    scene = js.string_pendulum("displacement", k=14, EA=1e4, t1=0.3)
    probed = eqx.tree_at(lambda s: s.effects, scene, scene.effects + (ZeroLoad(),))
    # Every other save time of the reference: a new shape, so that this solve is
    # traced here (a Kvaerno5 run would otherwise reuse the reference's compiled
    # solve: tolerances are not static).
    kw = dict(rtol=1e-8, atol=1e-8, ts=ref.ts[::2])
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
    err = float(np.max(np.linalg.norm(a.end_mass - ref.end_mass[::2], axis=1)))
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
    J = _dense_jacobian(scene, y + a * dt * f, t)
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


@pytest.mark.parametrize("second_order", [0, 3])
def test_bordered_jacobian_and_solve_equal_dense(second_order):
    # A vessel row (the border) coupled to two chains of springs at scattered rows,
    # the chains' rows (q, v) banded with width 1: the bordered Jacobian equals
    # jacfwd and its Schur-complement solve equals the dense solve.
    rng = np.random.default_rng(7)
    n, k = 9, 1
    K = jnp.asarray(rng.uniform(1.0, 3.0, n - k))
    hook = np.zeros(n - k)
    hook[[0, 5]] = 1.0  # the border pulls these nodes
    hook = jnp.asarray(hook)

    def fn(y):
        vb, q, v = y[:k], y[k:, :3], y[k:, 3:]
        qp = jnp.concatenate([q[:1], q[:-1]])
        qn = jnp.concatenate([q[1:], q[-1:]])
        a = K[:, None] * (qp - 2 * q + qn) + hook[:, None] * (vb[0, :3] - q) ** 3
        dv = a - 0.1 * v
        db = jnp.concatenate([vb[0, 3:], -jnp.sum(hook[:, None] * (vb[0, :3] - q), 0)])
        return jnp.concatenate([db[None], jnp.concatenate([v, dv], axis=1)])

    y = jnp.asarray(rng.standard_normal((n, 6)))
    spec = _linalg.BorderedWidth(width=1, border=k)
    # compiled, as the solvers run them (op by op, each operation compiles apart)
    mat = jax.jit(lambda u: _linalg.jacobian(fn, u, spec, second_order=second_order))(y)
    assert isinstance(mat, _linalg.BorderedJacobian)
    J = np.asarray(
        jax.jit(jax.jacfwd(lambda u: fn(u.reshape(y.shape)).reshape(-1)))(y.reshape(-1))
    )
    as_dense = jax.jit(lambda m: m.to_dense())(mat)
    np.testing.assert_allclose(np.asarray(as_dense), J, atol=1e-13)
    solve = jax.jit(lambda m, a, b, r: _linalg.factor(m.scale_shift(a, b)).solve(r))
    for a, b in ((1.0, -0.05), (20.0, -1.0)):
        rhs = rng.standard_normal(y.shape)
        x = np.asarray(solve(mat, a, b, jnp.asarray(rhs))).reshape(-1)
        dense = np.linalg.solve(a * np.eye(y.size) + b * J, rhs.reshape(-1))
        np.testing.assert_allclose(x, dense, rtol=1e-11, atol=1e-12)
