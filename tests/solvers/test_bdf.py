"""Variable-order BDF (jaxstring._solvers.bdf): convergence order, accuracy against
references, the stiff string pendulum, steps against scipy's BDF, grad and vmap."""

from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import jaxstring as js
from jaxstring._solvers.bdf import BDF

from ..helpers import fitted_order


# ---------------------------------------------------------------------------
# A linear stiff system with a forcing term (eigenvalues -1000, -2, -0.5)
# ---------------------------------------------------------------------------

_A = np.array([[-1000.0, 1.0, 0.0], [0.0, -2.0, 1.0], [0.0, 0.0, -0.5]])
_Y0 = np.array([1.0, 1.0, 1.0])
_T1 = 5.0


def _linear(t, y, args):
    del args
    return jnp.asarray(_A) @ y + jnp.sin(t)


@pytest.fixture(scope="module")
def linear_reference():
    sol = solve_ivp(
        lambda t, y: _A @ y + np.sin(t),
        (0.0, _T1),
        _Y0,
        method="Radau",
        rtol=1e-13,
        atol=1e-13,
    )
    return sol.y[:, -1]


def _bdf_solve(f, y0, t1, tol, **bdf):
    """diffrax's solve of dy/dt = f(t, y) from 0 to t1 with `BDF(**bdf)` at rtol =
    atol = tol and its PID controller."""
    return dfx.diffeqsolve(
        dfx.ODETerm(f),
        BDF(rtol=tol, atol=tol, **bdf),
        0.0,
        t1,
        None,
        jnp.asarray(y0),
        stepsize_controller=dfx.PIDController(rtol=tol, atol=tol),
        max_steps=1_000_000,
    )


@eqx.filter_jit
def _solve_linear(tol, max_order):
    # tol is an array: one compilation per max_order.
    return _bdf_solve(_linear, _Y0, _T1, tol, max_order=max_order)


def _nonlinear(t, y, args):
    # a stiff system whose Jacobian changes with the state (Robertson's kinetics)
    del t, args
    a, b, c = y[0], y[1], y[2]
    return jnp.stack(
        [
            -0.04 * a + 1e4 * b * c,
            0.04 * a - 1e4 * b * c - 3e7 * b**2,
            3e7 * b**2,
        ]
    )


def test_kept_jacobian_refactorised_on_a_change_of_c():
    # `keep_jacobian`: a change of c factorises the stored J again (CVODE) rather
    # than taking a fresh one. With a constant J (the linear system) that is the
    # same matrix: the same steps and solution. On Robertson's stiff kinetics
    # (J changes with the state) both reach scipy's Radau at 1e-12 within the
    # tolerance's error, with similar step counts.
    def run(f, y0, t1, tol, keep):
        sol = _bdf_solve(f, y0, t1, tol, keep_jacobian=keep)
        return np.asarray(sol.ys[-1]), int(sol.stats["num_steps"])

    (y_keep, n_keep), (y_fresh, n_fresh) = (
        run(_linear, _Y0, _T1, 1e-6, keep) for keep in (True, False)
    )
    assert n_keep == n_fresh
    np.testing.assert_allclose(y_keep, y_fresh, rtol=1e-10, atol=1e-14)

    y0 = np.array([1.0, 0.0, 0.0])
    ref = solve_ivp(
        lambda t, y: np.asarray(_nonlinear(t, y, None)),
        (0.0, 40.0),
        y0,
        method="Radau",
        rtol=1e-12,
        atol=1e-14,
    ).y[:, -1]
    steps = []
    for keep in (True, False):
        y, n = run(_nonlinear, y0, 40.0, 1e-6, keep)
        assert np.max(np.abs(y - ref) / (1e-6 + 1e-6 * np.abs(ref))) < 5, (keep, y)
        steps.append(n)
    assert abs(steps[0] - steps[1]) <= 0.25 * steps[1], steps
    with pytest.raises(ValueError, match="keep_jacobian"):
        BDF(keep_jacobian="sometimes")


@pytest.mark.parametrize(
    "max_order",
    [
        1,
        pytest.param(2, marks=pytest.mark.slow),
        pytest.param(3, marks=pytest.mark.slow),
        5,
    ],
)
def test_order_of_convergence(linear_reference, max_order):
    # Error against the number of steps falls like N^-q at fixed max order q
    # (start-up at order 1 and the adaptive steps make higher orders noisier).
    errors, steps = [], []
    for tol in (1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
        sol = _solve_linear(jnp.asarray(tol), max_order)
        assert sol.result == dfx.RESULTS.successful
        errors.append(float(np.max(np.abs(np.asarray(sol.ys[-1]) - linear_reference))))
        steps.append(int(sol.stats["num_accepted_steps"]))
    order = -fitted_order(steps, errors)
    assert max_order - 0.5 <= order <= max_order + 1.5, (order, errors, steps)


def test_accuracy_tracks_tolerance(linear_reference):
    # Local error control: the global error stays within a small multiple of the
    # tolerance and falls with it.
    tols = (1e-6, 1e-7, 1e-8, 1e-9)
    errors = []
    for tol in tols:
        sol = _solve_linear(jnp.asarray(tol), 5)
        errors.append(float(np.max(np.abs(np.asarray(sol.ys[-1]) - linear_reference))))
    assert all(e <= 50 * t for e, t in zip(errors, tols)), errors
    assert fitted_order(tols, errors) >= 0.7, errors


def test_fixed_step_order_two():
    # With a constant step (no controller decisions) and max_order = 2 the scheme is
    # the order-2 NDF after its order-1 start: global error O(h^2).
    lam = -3.0

    def vf(t, y, args):
        return lam * y + jnp.cos(t)

    def exact(t):
        # y' = lam y + cos t, y(0) = 1
        a = (-lam * np.cos(t) + np.sin(t)) / (lam**2 + 1)
        return (1 + lam / (lam**2 + 1)) * np.exp(lam * t) + a

    errs = []
    hs = (0.02, 0.01, 0.005)
    for h in hs:
        sol = dfx.diffeqsolve(
            dfx.ODETerm(vf),
            BDF(rtol=1e-12, atol=1e-12, max_order=2),
            0.0,
            1.0,
            jnp.asarray(h),
            jnp.array([1.0]),
            stepsize_controller=dfx.ConstantStepSize(),
        )
        errs.append(abs(float(sol.ys[-1, 0]) - exact(1.0)))
    assert 1.7 <= fitted_order(hs, errs) <= 2.3, errs


# ---------------------------------------------------------------------------
# The stiff string pendulum
# ---------------------------------------------------------------------------


def _pendulum(EA, t1, k=8):
    """Scene and 26 save times: every pendulum test has the same shapes, so the
    compiled `simulate` of each solver is shared (EA and t1 are leaves)."""
    scene = js.string_pendulum("displacement", k=k, EA=EA, t1=t1)
    return scene, jnp.linspace(0.0, t1, 26)


def test_pendulum_agrees_with_rodas5p_at_tight_tolerance():
    # Two independent methods at rtol = atol = 1e-9: both are within ~1e-8 of a
    # 1e-12 reference (measured), so they agree to well below 1e-7 m.
    scene, ts = _pendulum(1e6, 0.25)
    bdf = js.simulate(scene, "bdf", rtol=1e-9, atol=1e-9, ts=ts)
    rodas = js.simulate(scene, "rodas5p", rtol=1e-9, atol=1e-9, ts=ts)
    assert bdf.ok and rodas.ok
    diff = np.max(np.linalg.norm(np.asarray(bdf.end_mass - rodas.end_mass), axis=-1))
    assert diff < 1e-7, diff


def test_pendulum_ea_1e9_no_nan():
    scene, ts = _pendulum(1e9, 0.5)
    bdf = js.simulate(scene, "bdf", rtol=1e-6, atol=1e-6, ts=ts)
    assert bdf.ok, bdf.status
    assert np.all(np.isfinite(np.asarray(bdf.ys)))
    ref = js.simulate(scene, "rodas5p", rtol=1e-9, atol=1e-9, ts=ts)
    err = np.max(np.linalg.norm(np.asarray(bdf.end_mass - ref.end_mass), axis=-1))
    assert err < 1e-4, err


def test_steps_comparable_to_scipy_bdf():
    # Same algorithm as scipy's BDF (exact Jacobian given to both): the number of
    # accepted steps at rtol = atol = 1e-6 should be similar (measured 388 vs 478).
    scene, ts = _pendulum(1e6, 1.0)
    shape = scene.y0.shape
    f = jax.jit(lambda t, y: scene.vector_field(t, y.reshape(shape)).reshape(-1))
    jac = jax.jit(
        jax.jacfwd(lambda y, t: scene.vector_field(t, y.reshape(shape)).reshape(-1))
    )
    # scipy's BDF can form an invalid value in the slot of its difference table one
    # above the current order (used only to weigh raising the order); whether that
    # warning fires depends on the CPU's rounding, so it is silenced for the
    # reference alone. The result is still checked to be finite and successful.
    with np.errstate(invalid="ignore", over="ignore"):
        ref = solve_ivp(
            lambda t, y: np.asarray(f(t, y)),
            (0.0, 1.0),
            np.asarray(scene.y0).reshape(-1),
            method="BDF",
            rtol=1e-6,
            atol=1e-6,
            jac=lambda t, y: np.asarray(jac(y, t)),
        )
    assert ref.success and np.all(np.isfinite(ref.y[:, -1]))
    n_scipy = len(ref.t) - 1
    traj = js.simulate(scene, "bdf", rtol=1e-6, atol=1e-6, ts=ts)
    assert traj.ok
    n_ours = int(traj.stats["num_accepted_steps"])
    assert 0.5 * n_scipy <= n_ours <= 1.5 * n_scipy, (n_ours, n_scipy)
    # and the same end state to tolerance level
    end = np.asarray(traj.ys[-1]).reshape(-1)
    assert np.max(np.abs(end - ref.y[:, -1])) < 1e-3


# ---------------------------------------------------------------------------
# jit / vmap / grad
# ---------------------------------------------------------------------------


def _end_y(g, solver="bdf"):
    """End-mass height at 0.2 s as a function of gravity g (about -g t^2 / 2)."""
    base = js.string_pendulum("displacement", k=4, EA=1e4, t1=0.2)
    scene = eqx.tree_at(lambda s: s.env.g, base, g)
    ts = jnp.array([0.0, 0.2])
    traj = js.simulate(scene, solver, rtol=1e-10, atol=1e-10, ts=ts)
    return traj.end_mass[-1, 1]


@pytest.mark.slow
def test_grad_matches_finite_differences():
    # Slow through compilation only (reverse mode through diffrax and custom_root,
    # 30-90 s on a loaded 2-core machine).
    g0 = jnp.asarray(9.81)
    grad = float(jax.grad(_end_y)(g0))
    h = 1e-3
    fd = float((_end_y(g0 + h) - _end_y(g0 - h)) / (2 * h))
    assert np.isfinite(grad)
    assert abs(grad) > 1e-3  # a real sensitivity, not noise
    assert abs(grad - fd) <= 1e-5 * abs(fd), (grad, fd)


@pytest.mark.slow
def test_vmap_equals_loop():
    # Slow through compilation only (the batched and the unbatched solve).
    xs = jnp.array([9.81, 3.71])
    batched = np.asarray(jax.vmap(_end_y)(xs))
    looped = np.array([float(_end_y(x)) for x in xs])
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-9)


def test_bad_arguments_raise():
    with pytest.raises(ValueError, match="max_order"):
        BDF(max_order=6)
    with pytest.raises(ValueError, match="linear_solver"):
        BDF(linear_solver="sparse")


# ---------------------------------------------------------------------------
# Stability guard: MoorDyn's test-suite pendulum
# ---------------------------------------------------------------------------


class _EndWeight(js.AbstractStringLoad):
    """The end mass's weight only (a neutrally buoyant line)."""

    weight: jnp.ndarray = eqx.field(converter=jnp.asarray)
    constant: ClassVar[bool] = True

    def forces(self, t, kin, env):
        del t, env
        end = jnp.zeros((kin.positions.shape[-1],)).at[1].set(-self.weight)
        return js.Loads(line=jnp.zeros_like(kin.positions), end=end)


def _moordyn_pendulum(k=10, t1=20.0):
    # experiments/moordyn_pendulum.py with k = 10: 100.5 m, EA = 1e9 N, 7.85 kg/m,
    # 1e5 kg end mass released from (10, -100) m, 1 % segment damping, the line
    # straight and stretched under the weight's radial part. Its axial modes are
    # lightly damped (zeta ~ 0.01) and its transverse modes undamped: eigenvalues
    # within 0.6 degrees of the imaginary axis.
    l, EA, w, m, g = 100.5, 1e9, 7.85398, 1e5, 9.81
    alpha = 0.01 * (l / k) * np.sqrt(EA * w) / EA
    d = np.hypot(10.0, 100.0)
    stretch = 1.0 + m * g * (100.0 / d) / EA
    r = (
        np.linspace(0, 1, k + 1)[1:, None]
        * np.array([[10.0, -100.0]])
        * (l * stretch / d)
    )
    y0 = np.concatenate([r, np.zeros_like(r)], axis=1)
    return js.string_pendulum(
        k=k,
        EA=EA,
        alpha=alpha,
        l=l,
        mu=w,
        m_s=m,
        t1=t1,
        effects=(_EndWeight(weight=m * g), js.KelvinVoigt(alpha=alpha)),
        y0=jnp.asarray(y0),
    )


def test_moordyn_pendulum_stability_guard():
    # Orders 3-5 are unstable for h omega in a band on the imaginary axis (NDF3:
    # 0.01 < h omega < 3.4, NDF5: 0.7 ... 9.3). Without the guard the step collapsed
    # to ~1e-4 s at orders 3-4 and bdf hit max_steps (here 20k steps by t = 20 s,
    # at both tolerances); Rodas5P needs 201 / 929 steps. With it bdf finishes in
    # 719 / 7499 steps with end-mass errors 1.0e-3 m (rtol 1e-4) and 6.9e-6 m
    # (rtol 1e-6) against Rodas5P at 1e-10 (positions ~100 m: relative 1e-5, 7e-8).
    scene = _moordyn_pendulum()
    ts = jnp.linspace(0.0, 20.0, 101)
    ref = js.simulate(
        scene, "rodas5p", rtol=1e-10, atol=1e-10, ts=ts, max_steps=200_000
    )
    assert ref.ok
    for tol, bound in ((1e-4, 5e-3), (1e-6, 5e-5)):
        traj = js.simulate(scene, "bdf", rtol=tol, atol=tol, ts=ts, max_steps=20_000)
        assert traj.ok, (tol, traj.status, traj.stats)
        err = float(jnp.max(jnp.linalg.norm(traj.end_mass - ref.end_mass, axis=-1)))
        assert err < bound, (tol, err)


def _final_refresh_count(formulation, skip_after, reuse=True):
    """BDF on the k = 8 pendulum through diffrax, returning the end state and the
    solver's count of accepted steps in a row that needed a fresh Jacobian."""
    from jaxstring._scene import scene_vector_field
    from jaxstring._solvers import bdf as _bdf

    scene = js.string_pendulum(formulation, k=8, EA=1e6, t1=0.3)
    old = _bdf._SKIP_STORED_AFTER
    _bdf._SKIP_STORED_AFTER = skip_after  # read at trace time
    try:
        sol = dfx.diffeqsolve(
            dfx.ODETerm(scene_vector_field),
            BDF(rtol=1e-7, atol=1e-7, reuse_jacobian=reuse),
            0.0,
            0.3,
            None,
            scene.y0,
            args=scene,
            stepsize_controller=dfx.PIDController(rtol=1e-7, atol=1e-7),
            saveat=dfx.SaveAt(t1=True, solver_state=True),
            max_steps=20_000,
        )
    finally:
        _bdf._SKIP_STORED_AFTER = old
    assert sol.result == dfx.RESULTS.successful
    return (
        np.asarray(sol.ys[-1]),
        int(np.ravel(sol.solver_state.n_refresh)[-1]),
        sol.stats,
    )


@pytest.mark.slow
def test_stored_jacobian_skipped_only_where_it_keeps_failing():
    # Displacement variables: the springs turn with the string, so the stored
    # Jacobian nearly never contracts the Newton iteration; BDF then stops trying it
    # first (it ends the run deep in a streak of refreshed steps) and takes the same
    # steps to the same solution. Natural variables: the stored one works, no streak.
    y_skip, n_skip, st_skip = _final_refresh_count("displacement", 4)
    y_try, _, st_try = _final_refresh_count("displacement", 10**9)
    assert n_skip > 20, n_skip
    assert int(st_skip["num_steps"]) == int(st_try["num_steps"])
    assert np.max(np.abs(y_skip - y_try)) < 1e-9
    # Without a stored Jacobian at all (`reuse_jacobian=False`, what `simulate`
    # builds for the displacement string): the steps and solution of the skipping
    # path up to its rare retries of the stored one (a step or two; tolerance 1e-7).
    y_fresh, _, st_fresh = _final_refresh_count("displacement", 4, reuse=False)
    assert abs(int(st_fresh["num_steps"]) - int(st_skip["num_steps"])) <= 2
    assert np.max(np.abs(y_fresh - y_skip)) < 1e-6, np.max(np.abs(y_fresh - y_skip))
    _, n_angle, _ = _final_refresh_count("angle", 4)
    assert n_angle < 4, n_angle


def _scipy_step(D, order, factor, d):
    """scipy's BDF on a 2D difference array: its own ``change_D``, then the
    predictor, history term and accepted-step update of ``BDF._step_impl``
    (``scipy/integrate/_ivp/bdf.py``), written out with numpy."""
    from scipy.integrate._ivp.bdf import change_D

    from jaxstring._solvers.bdf import _ALPHA, _GAMMA

    D = np.array(D)
    change_D(D, order, factor)
    y_pred = np.sum(D[: order + 1], axis=0)
    psi = np.dot(D[1 : order + 1].T, _GAMMA[1 : order + 1]) / _ALPHA[order]
    D[order + 2] = d - D[order + 1]
    D[order + 1] = d
    for i in reversed(range(order + 1)):
        D[i] += D[i + 1]
    return y_pred, psi, D


@pytest.mark.parametrize("order", [1, 2, 3, 4, 5])
def test_step_weights_equal_scipys_difference_updates(order):
    """The step's linear maps on the rows of D (`_step_weights`: the rescaling
    folded into the predictor, the history term and the update of an accepted
    step, applied by the unrolled `_combine`) give scipy's BDF sequence on the
    rescaled array, to rounding, for shrinking, equal and growing steps."""
    from jaxstring._solvers.bdf import _combine, _step_weights

    rng = np.random.default_rng(order)
    D = rng.standard_normal((8, 28))  # 2D, as scipy's change_D expects
    d = rng.standard_normal(28)
    for factor in (0.4, 1.0, 1.9):
        W, e, w_pred, w_psi = _step_weights(
            jnp.asarray(order), jnp.asarray(factor), jnp.float64
        )
        y_ref, psi_ref, D_ref = _scipy_step(D, order, factor, d)
        Dj = jnp.asarray(D)
        np.testing.assert_allclose(_combine(w_pred, Dj), y_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(_combine(w_psi, Dj), psi_ref, rtol=0, atol=1e-12)
        D_acc = _combine(W, Dj) + e[:, None] * d
        np.testing.assert_allclose(D_acc, D_ref, rtol=0, atol=1e-12)
