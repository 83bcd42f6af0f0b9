"""Solvers by name, the fixed-step paper setting, failure reporting, stage Newton."""

import diffrax as dfx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring._solvers.fixed_step import _newton

from ..helpers import fitted_order, run


def _err(traj, ref):
    return float(np.max(np.linalg.norm(traj.end_mass - ref.end_mass, axis=1)))


@pytest.mark.parametrize(
    "solver, tol",
    [
        ("kvaerno3", 1e-5),
        pytest.param("kvaerno4", 1e-5, marks=pytest.mark.slow),  # order: test_esdirk
        ("implicit_euler", 1e-2),
        ("tsit5", 1e-5),
        ("dopri5", 1e-5),
    ],
)
def test_adaptive_solvers_agree_with_reference(solver, tol):
    # Soft string (explicit solvers need no more than a few thousand steps).
    ref = run("displacement", k=6, EA=1e3, t1=0.5, n_save=51, rtol=1e-11, atol=1e-11)
    traj = run(
        "displacement",
        k=6,
        EA=1e3,
        t1=0.5,
        n_save=51,
        solver=solver,
        rtol=1e-7,
        atol=1e-7,
    )
    assert traj.ok, traj.status
    assert _err(traj, ref) < tol, _err(traj, ref)


# The fixed-step methods' orders: test_fast_solvers (damped oscillator, string).
@pytest.mark.slow
def test_fixed_step_implicit_euler_paper_setting_first_order():
    # The paper's fixed step dt = 0.005 (400 steps over 2 s) must run, and the
    # error must fall like dt.
    scene = js.string_pendulum(k=10, EA=1e4, t1=0.4)
    ts = jnp.linspace(0.0, 0.4, 5)
    ref = js.simulate(scene, rtol=1e-11, atol=1e-11, ts=ts)
    dts = (0.005, 0.0025, 0.00125)
    errs = []
    for dt in dts:
        traj = js.simulate(
            scene, "implicit_euler_fixed", dt0=dt, rtol=1e-7, atol=1e-7, ts=ts
        )
        assert traj.ok, traj.status
        assert int(traj.stats["num_accepted_steps"]) == round(0.4 / dt)
        errs.append(_err(traj, ref))
    order = fitted_order(dts, errs)
    assert 0.8 < order < 1.3, (order, errs)
    paper = js.simulate(
        js.string_pendulum(k=10, EA=1e6, t1=2.0),
        "implicit_euler_fixed",
        dt0=0.005,
        rtol=1e-7,
        atol=1e-7,
        ts=jnp.linspace(0.0, 2.0, 5),  # as many save times: the same program
    )
    assert paper.ok and int(paper.stats["num_accepted_steps"]) == 400


def test_failed_solve_returns_status_and_data_up_to_failure():
    # An explicit solver on a stiff string runs out of steps: no exception, a
    # status message, the data up to the failure and NaN afterwards.
    traj = run(
        "displacement",
        k=10,
        EA=1e6,
        solver="tsit5",
        max_steps=300,
        n_save=101,
        rtol=1e-6,
        atol=1e-6,
    )
    assert not traj.ok
    assert "maximum number of solver steps" in traj.status
    n = int(traj.n_valid)
    assert 1 <= n < 101
    assert np.all(np.isfinite(np.asarray(traj.positions[:n])))
    assert np.all(np.isnan(np.asarray(traj.positions[n:])))
    assert 0.0 <= float(traj.t_end) < 1.0


@pytest.mark.slow
def test_stage_newton_avoids_veryChord_early_divergence():
    # diffrax 0.7.2's VeryChord declares divergence whenever Newton has not met its
    # tolerance after two iterations, so it rejects many steps that a contracting
    # iteration would have accepted. jaxstring's StageNewton keeps iterating.
    scene = js.string_pendulum(k=6, EA=1e4, t1=0.5)
    ts = jnp.linspace(0.0, 0.5, 11)
    released = js.simulate(scene, dfx.Kvaerno5(), rtol=1e-6, atol=1e-6, ts=ts)
    ours = js.simulate(scene, "kvaerno5", rtol=1e-6, atol=1e-6, ts=ts)
    ref = js.simulate(scene, rtol=1e-11, atol=1e-11, ts=ts)
    assert released.ok and ours.ok
    rej_released = int(released.stats["num_rejected_steps"])
    rej_ours = int(ours.stats["num_rejected_steps"])
    assert rej_ours * 3 < rej_released, (rej_ours, rej_released)
    assert int(ours.stats["num_steps"]) < int(released.stats["num_steps"])
    assert _err(ours, ref) < 1e-4


@pytest.mark.parametrize(
    "formulation",
    [
        pytest.param("natural", marks=pytest.mark.slow),
        pytest.param("displacement", marks=pytest.mark.slow),
    ],
)
def test_fixed_step_newton_variants_solve_the_same_steps(formulation):
    # newton="chord": one factorisation per step and simplified Newton updates; in
    # natural variables they converge, in displacement variables at EA = 1e6 they
    # diverge (the stiff axis turns with the string) and the damped full Newton
    # takes over. Either way each step's implicit equation is solved to the same
    # test, so with a 1e-10 Newton tolerance the two trajectories agree to ~1e-10
    # (the iteration error), far below implicit Euler's own error at dt = 0.005.
    # The same holds for the Newton start: extrapolated from the previous step's
    # increment (the default) or zero.
    scene = js.string_pendulum(formulation=formulation, k=8, EA=1e6, t1=0.5)
    out = {}
    for newton, extrapolate in (("full", True), ("chord", True), ("full", False)):
        solver = js.ThetaMethod(
            theta=1.0, rtol=1e-10, atol=1e-10, newton=newton, extrapolate=extrapolate
        )
        key = (newton, extrapolate)
        out[key] = js.simulate(scene, solver, dt0=0.005, n_save=26)
        assert out[key].ok, out[key].status
    assert _err(out[("chord", True)], out[("full", True)]) < 1e-9
    assert _err(out[("full", False)], out[("full", True)]) < 1e-9
    with pytest.raises(ValueError, match="newton"):
        js.ThetaMethod(theta=1.0, newton="quasi")


def test_newton_restarts_from_the_plain_start_when_the_predicted_one_fails():
    # ThetaMethod starts each step's Newton iteration from the previous increment
    # (a prediction) and keeps the plain start (zero increment) as a restart point.
    # Newton on arctan(x) = 0 from x = 1e3 overshoots to |x| ~ 1e6 and overflows
    # even with damping; from the restart point x = 0.5 it converges to the root.
    res = lambda x, a: jnp.arctan(x)
    x0, restart = jnp.array([1e3]), jnp.array([0.5])
    kw = dict(rtol=1e-12, atol=1e-12, kappa=0.1, max_iters=100, linear_solver="dense")
    x, ok = _newton(res, x0, None, lambda x: x, **kw)
    assert not bool(ok) and not np.isfinite(float(x[0]))
    x, ok = _newton(res, x0, None, lambda x: x, **kw, x_restart=restart)
    assert bool(ok) and abs(float(x[0])) < 1e-12
