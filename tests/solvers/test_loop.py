"""jaxstring's own step loop (`jaxstring._solvers.loop`) against diffrax's: a solve
that reverse mode does not differentiate runs the same steps with the same
solver, controller and clipping, so its saved states, step counts and status equal
those of `diffeqsolve` exactly, from a smaller program; a solve under `vmap` keeps
diffrax's loop."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _integrate
from jaxstring._solvers import loop

from ..helpers import count_eqns


def _values(scene, config, ts, own_loop, monkeypatch):
    """The solve's Trajectory (values only) through one loop or the other, from a
    trace of its own."""
    with monkeypatch.context() as m:
        if not own_loop:
            m.setattr(loop, "serves", lambda *args: False)
        run = jax.jit(lambda sc, c, t: _integrate.solve(sc, c, t, differentiable=False))
        return run(scene, config, ts)


@pytest.mark.parametrize(
    "formulation, solver, options",
    [
        ("displacement", "kvaerno5", {}),  # diffrax's Kvaerno, a Jacobian per stage
        ("natural", "kvaerno5", {"project": True}),  # jaxstring's ESDIRK, projected
        ("displacement", "rodas5p", {}),
        ("displacement", "bdf", {}),
        ("displacement", "implicit_euler_fixed", {"dt0": 0.01}),  # constant step
        ("displacement", "tsit5", {}),  # explicit, PID controller
    ],
)
def test_the_own_loop_gives_diffrax_loops_values_exactly(
    formulation, solver, options, monkeypatch
):
    scene = js.string_pendulum(formulation=formulation, k=4, EA=1e4, t1=0.2)
    config = js.SolveConfig(solver=solver, rtol=1e-6, atol=1e-6, **options)
    ts = jnp.linspace(0.0, 0.2, 9)
    own, theirs = (_values(scene, config, ts, o, monkeypatch) for o in (True, False))
    assert own.ok and theirs.ok
    assert int(own.stats["num_steps"]) > 8
    for key in ("num_steps", "num_accepted_steps", "num_rejected_steps"):
        assert int(own.stats[key]) == int(theirs.stats[key]), key
    np.testing.assert_array_equal(np.asarray(own.ys), np.asarray(theirs.ys))
    assert np.ptp(np.asarray(own.end_mass)[:, 1]) > 1e-3  # it really moves


def test_a_solve_that_runs_out_of_steps_stops_where_diffraxs_does(monkeypatch):
    scene = js.string_pendulum(k=4, EA=1e4, t1=0.5)
    config = js.SolveConfig(solver="kvaerno5", rtol=1e-8, atol=1e-8, max_steps=12)
    ts = jnp.linspace(0.0, 0.5, 33)
    own, theirs = (_values(scene, config, ts, o, monkeypatch) for o in (True, False))
    assert not own.ok and own.status == theirs.status
    assert "maximum number of solver steps" in own.status
    assert int(own.stats["num_steps"]) == int(theirs.stats["num_steps"]) == 12
    assert 0 < int(own.n_valid) == int(theirs.n_valid) < 33
    np.testing.assert_array_equal(np.asarray(own.ys), np.asarray(theirs.ys))
    n = int(own.n_valid)
    assert np.isinf(np.asarray(own.ys)[n:]).all()  # rows not reached, as diffrax's
    assert np.isnan(np.asarray(own.end_mass)[n:]).all()
    assert np.isfinite(np.asarray(own.end_mass)[:n]).all()


def test_the_own_loop_is_the_smaller_program(monkeypatch):
    # The same solve traced through each loop: diffrax's carries equinox's
    # rewritten while loops and 100 steps of t1 less 100 ULP.
    scene = js.string_pendulum(k=4, EA=1e4, t1=0.2)
    config = js.SolveConfig(solver="kvaerno5", rtol=1e-6, atol=1e-6)
    ts = jnp.linspace(0.0, 0.2, 9)

    sizes = []
    for own_loop in (True, False):
        with monkeypatch.context() as m:
            if not own_loop:
                m.setattr(loop, "serves", lambda *args: False)
            fn = lambda sc: _integrate.solve(sc, config, ts, differentiable=False).ys
            sizes.append(count_eqns(jax.make_jaxpr(fn)(scene).jaxpr))
    assert sizes[0] < 0.7 * sizes[1], sizes  # measured: 1319 against 2063


def test_a_forward_mode_derivative_through_the_own_loop_matches_differences(
    monkeypatch,
):
    # A solve with forward-mode derivatives (adjoint "forward") runs the own loop
    # under jax.jvp: the derivative of the end mass's reach with respect to the
    # axial stiffness against a central difference.
    solves = []
    own_solve = loop.solve
    monkeypatch.setattr(
        loop, "solve", lambda *a, **k: solves.append(1) or own_solve(*a, **k)
    )
    scene = js.string_pendulum(k=4, EA=1e4, alpha=0.05, t1=0.2)
    config = js.SolveConfig(
        solver="kvaerno5", rtol=1e-10, atol=1e-10, adjoint="forward"
    )
    ts = jnp.linspace(0.0, 0.2, 5)

    def reach(EA):
        sc = eqx.tree_at(lambda s: s.model.EA, scene, EA)
        return _integrate.solve(sc, config, ts).end_mass[-1, 0]

    _, tangent = jax.jit(lambda x: jax.jvp(reach, (x,), (1.0,)))(jnp.float64(1e4))
    assert solves  # traced through the own loop
    h = 1.0
    run = jax.jit(reach)
    diff = (run(1e4 + h) - run(1e4 - h)) / (2 * h)
    assert abs(float(diff)) * 1e4 > 1e-4  # the stiffness moves the end mass
    assert abs(float(tangent) - float(diff)) <= 1e-5 * abs(float(diff))


def test_members_under_vmap_get_diffrax_loops_values_exactly(monkeypatch):
    # A sweep's members: the own loop under vmap (equinox's buffered loops, a
    # saved row written at a time) against diffrax's, member by member; members
    # take different numbers of steps.
    scene = js.string_pendulum(k=4, EA=1e4, t1=0.2)
    config = js.SolveConfig(solver="kvaerno5", rtol=1e-6, atol=1e-6)
    ts = jnp.linspace(0.0, 0.2, 9)
    alphas = jnp.array([0.001, 0.05, 0.3])

    def members(own_loop):
        with monkeypatch.context() as m:
            if not own_loop:
                m.setattr(loop, "serves", lambda *args: False)

            def member(alpha):
                sc = eqx.tree_at(lambda s: s.effects[1].alpha, scene, alpha)
                traj = _integrate.solve(
                    sc, config, ts, differentiable=False, batched=True
                )
                return traj.ys, traj.stats["num_steps"]

            return jax.jit(jax.vmap(member))(alphas)

    (own, own_steps), (theirs, their_steps) = members(True), members(False)
    np.testing.assert_array_equal(np.asarray(own_steps), np.asarray(their_steps))
    assert len(set(np.asarray(own_steps).tolist())) > 1
    np.testing.assert_array_equal(np.asarray(own), np.asarray(theirs))
    assert np.isfinite(np.asarray(own)).all()
