"""The written-out Kvaerno ESDIRKs: order, the same steps as diffrax's, stiffness,
the solver `simulate` picks, and gradients."""

import math

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _fit
from jaxstring._scene import scene_vector_field
from jaxstring._solvers.esdirk import ESDIRK
from jaxstring._solvers.registry import build_solver
from jaxstring._solvers.stage_newton import StageNewton

from ..helpers import assert_grad_matches_central_differences, fitted_order


def _logistic(t, y, args):
    del t, args
    return y * (1 - y)


def _logistic_exact(t):
    return 1 / (1 + 9 * math.exp(-t))


def _fixed(solver, vf, y0, h, t1):
    sol = dfx.diffeqsolve(dfx.ODETerm(vf), solver, 0.0, t1, h, y0)
    assert sol.result == dfx.RESULTS.successful
    return np.asarray(sol.ys[-1])


@pytest.mark.parametrize(
    "method, order",
    [pytest.param("kvaerno3", 3, marks=pytest.mark.slow),
     pytest.param("kvaerno4", 4, marks=pytest.mark.slow),
     ("kvaerno5", 5)],
)  # fmt: skip
def test_order_on_the_logistic_equation(method, order):
    # u' = u (1 - u), u(0) = 0.1, exact solution; fixed steps, tight stage solves.
    hs = (0.4, 0.2, 0.1, 0.05)
    solver = ESDIRK(method=method, rtol=1e-13, atol=1e-13)
    y0 = jnp.array([[0.1]])
    errs = [
        abs(_fixed(solver, _logistic, y0, h, 4.0)[0, 0] - _logistic_exact(4.0))
        for h in hs
    ]
    slope = fitted_order(hs, errs)
    assert abs(slope - order) < 0.4, (slope, errs)


@pytest.mark.parametrize(
    "method", [pytest.param("kvaerno3", marks=pytest.mark.slow), "kvaerno5"]
)
def test_same_steps_as_diffrax_kvaerno(method):
    # The same tableau: with the stage solves converged to rounding, the
    # written-out step and diffrax's generic Runge-Kutta step give the same
    # solution over 300 constant steps of the stiff string.
    sc = js.string_pendulum(formulation="angle", k=6, EA=1e6, t1=0.3)
    cls = {"kvaerno3": dfx.Kvaerno3, "kvaerno5": dfx.Kvaerno5}[method]
    theirs = cls(
        root_finder=StageNewton(rtol=1e-12, atol=1e-12), root_find_max_steps=10
    )
    mine = ESDIRK(method=method, rtol=1e-12, atol=1e-12)

    @jax.jit
    def run(y0, sc):
        out = []
        for solver in (mine, theirs):
            sol = dfx.diffeqsolve(
                dfx.ODETerm(scene_vector_field), solver, 0.0, 0.3, 1e-3, y0, sc,
                max_steps=400,
            )  # fmt: skip
            out.append(sol.ys[-1])
        return out

    a, b = run(sc.y0, sc)
    scale = float(jnp.max(jnp.abs(b)))
    assert float(jnp.max(jnp.abs(a - b))) < 1e-9 * scale
    # and both moved: the string swung through 0.3 s
    assert float(jnp.max(jnp.abs(b - sc.y0))) > 1e-2 * scale


def test_simulate_picks_the_written_out_solver_where_one_jacobian_serves_a_step():
    # Natural variables (stiff force linear in the state): the written-out ESDIRK;
    # the displacement string (stiff axis turning within a step): diffrax's Kvaerno
    # with a Jacobian at every stage.
    for form, cls in (
        ("angle", ESDIRK),
        ("natural", ESDIRK),
        ("displacement", dfx.Kvaerno5),
    ):
        sc = js.string_pendulum(formulation=form, k=4)
        assert isinstance(build_solver("kvaerno5", 1e-6, 1e-6, sc), cls), form


def test_agrees_with_rodas5p_reference_on_the_stiff_string():
    sc = js.string_pendulum(formulation="angle", k=10, EA=1e9, t1=0.5)
    ts = np.linspace(0.0, 0.5, 3)
    ref = js.simulate(sc, "rodas5p", rtol=1e-11, atol=1e-11, ts=ts)
    errs = []
    for tol in (1e-5, 1e-7):
        out = js.simulate(sc, "kvaerno5", rtol=tol, atol=tol, ts=ts)
        assert out.ok
        errs.append(
            float(np.max(np.abs(np.asarray(out.end_mass) - np.asarray(ref.end_mass))))
        )
    assert errs[1] < 1e-6, errs
    assert errs[1] < errs[0] / 10, errs


def _end_loss(traj, scene):
    del scene
    return jnp.sum(traj.obs["positions"][:, -1, :] ** 2) + 1e3 * jnp.max(
        traj.obs["strain"]
    )


@pytest.mark.slow
def test_reverse_mode_gradient_matches_central_differences():
    # d(loss)/d(alpha, EA) through the stage solves (custom_root), reverse mode.
    scene = js.string_pendulum(formulation="angle", k=4, EA=1e3, alpha=0.02, t1=0.3)
    kw = dict(rtol=1e-11, atol=1e-11, n_save=11, solver="kvaerno5")
    _, grad = _fit.value_and_grad(scene, _end_loss, ["alpha", "EA"], **kw)
    config = _fit.SolveConfig(**kw)
    assert_grad_matches_central_differences(
        lambda s: _end_loss(_fit.solve(s, config), s), scene, grad
    )
