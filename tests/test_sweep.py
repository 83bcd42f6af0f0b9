"""sweep: one compiled vmap over members equals a Python loop of simulate calls;
a failed member leaves the others intact; sharding over two CPU devices. The
lockstep mode (one shared step sequence) agrees with a tight reference to the
solver tolerance, as well as the loop does; its block-diagonal Newton linear algebra
equals per-member dense solves. With a fixed step (members' nodes concatenated into
one banded system) the lockstep sweep equals the loop to rounding."""

import textwrap

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _linalg
from jaxstring._solvers.stage_newton import batched_factor
from jaxstring._sweep import member_rms_max, sweep

from .helpers import run_on_two_cpu_devices


def _end_and_tension(traj, scene):
    del scene
    return {
        "end": traj.obs["positions"][:, -1, :],
        "T_max": jnp.max(traj.obs["tension"]),
    }


KW = dict(solver="kvaerno5", rtol=1e-9, atol=1e-9, n_save=11)


def test_sweep_matches_loop_of_simulate_calls():
    base = js.string_pendulum(
        formulation="displacement", k=3, EA=1e3, alpha=0.02, t1=0.2
    )
    alphas = np.linspace(0.005, 0.05, 4)
    EAs = np.array([5e2, 1e3, 2e3, 4e3])
    res = sweep(base, {"alpha": alphas, "EA": EAs}, _end_and_tension, devices=1, **KW)
    assert res.ok.all(), res.status
    for i, (a, ea) in enumerate(zip(alphas, EAs)):
        scene = js.string_pendulum(
            formulation="displacement", k=3, EA=ea, alpha=a, t1=0.2
        )
        traj = js.simulate(scene, **KW)
        ref = _end_and_tension(traj, scene)
        assert np.max(np.abs(res.out["end"][i] - np.asarray(ref["end"]))) < 1e-10
        assert abs(res.out["T_max"][i] - float(ref["T_max"])) < 1e-10 * float(
            ref["T_max"]
        )
        assert int(res.stats["num_steps"][i]) == int(traj.stats["num_steps"])


def test_failed_member_leaves_the_others_intact():
    base = js.string_pendulum(
        formulation="displacement", k=3, EA=1e3, alpha=0.02, t1=0.2
    )
    # Alone, the members need 101, 121 and 61 step attempts (simulate's defaults:
    # Newton-limited controller, a Kvaerno5 Jacobian at every stage, which makes the
    # nearly rigid EA = 1e11 string the cheapest), so max_steps = 110 stops member 1.
    EAs = np.array([1e3, 2e3, 1e11])
    res = sweep(base, {"EA": EAs}, _end_and_tension, devices=1, max_steps=110, **KW)
    assert res.ok.tolist() == [True, False, True], res.status
    assert "max_steps" in res.status[1] or "maximum" in res.status[1].lower()
    for i in (0, 2):
        scene = js.string_pendulum(
            formulation="displacement", k=3, EA=EAs[i], alpha=0.02, t1=0.2
        )
        ref = js.simulate(scene, max_steps=110, **KW)
        assert np.max(np.abs(res.out["end"][i] - np.asarray(ref.end_mass))) < 1e-10
    # The failed member keeps its valid rows and NaN after the failure.
    assert np.isnan(res.out["end"][1][-1]).all()


@pytest.mark.slow
def test_grid_shape_and_sharding_over_two_cpu_devices():
    # A fresh process: the device count is fixed when JAX starts.
    code = textwrap.dedent(
        """
        import numpy as np, jax, jax.numpy as jnp
        import jaxstring as js
        from jaxstring._sweep import sweep
        assert len(jax.devices()) == 2
        base = js.string_pendulum(k=3, EA=1e3, alpha=0.02, t1=0.2)
        fn = lambda traj, s: traj.obs["positions"][-1, -1, :]
        # groups of 3 members: two groups, one per device
        kw = dict(rtol=1e-9, atol=1e-9, n_save=11, batch_size=3)
        v = {"alpha": [0.01, 0.02, 0.04], "EA": [1e3, 2e3]}
        two = sweep(base, v, fn, grid=True, **kw)
        one = sweep(base, v, fn, grid=True, devices=1, **kw)
        assert two.n_devices == 2 and two.shape == (3, 2), (two.n_devices, two.shape)
        assert two.out.shape == (3, 2, 2)
        print(float(np.max(np.abs(two.out - one.out))))
        """
    )
    out = run_on_two_cpu_devices(code)
    assert float(out.strip().splitlines()[-1]) < 1e-12


@pytest.mark.slow
def test_bdf_groups_on_two_cpu_devices_repeat_and_match_one_device():
    # Two CPU devices, vmapped BDF groups of 16: with one dispatching thread per
    # device the second call of the same compiled sweep deadlocked inside XLA:CPU;
    # every call must finish and equal the one-device sweep.
    code = textwrap.dedent(
        """
        import numpy as np, jax
        import jaxstring as js
        from jaxstring._sweep import sweep
        assert len(jax.devices()) == 2
        base = js.string_pendulum(k=8, EA=1e6, t1=0.2)
        fn = lambda traj, s: traj.obs["positions"][:, -1, :]
        kw = dict(solver="bdf", rtol=1e-6, atol=1e-6, n_save=5, batch_size=16,
                  processes=1)
        v = {"alpha": np.linspace(0.005, 0.05, 32)}
        one = np.asarray(sweep(base, v, fn, devices=1, **kw).out)
        for _ in range(3):
            two = sweep(base, v, fn, **kw)
            assert two.n_devices == 2 and bool(np.all(two.ok))
            print(float(np.max(np.abs(np.asarray(two.out) - one))))
        """
    )
    diffs = [float(x) for x in run_on_two_cpu_devices(code, timeout=240).split()]
    assert len(diffs) == 3 and max(diffs) < 1e-12, diffs


def _pendulum(formulation="displacement", **kw):
    return js.string_pendulum(formulation=formulation, k=3, t1=0.3, **kw)


@pytest.mark.parametrize(
    "formulation", ["displacement", pytest.param("natural", marks=pytest.mark.slow)]
)
def test_lockstep_as_accurate_as_the_loop_against_a_tight_reference(formulation):
    # Members of different stiffness and damping take different step sequences
    # alone; lockstep gives them one, accepted only when every member's own error
    # norm passes. Each member must then be as accurate as its own solve (up to the
    # randomness of error estimates: factor 3) -- measured against Kvaerno5 at
    # rtol = atol = 1e-10 -- and within a tolerance-level distance of the loop.
    # "natural" also checks the projection onto |t| = 1 of each member.
    alphas = np.array([0.0, 0.01, 0.05])
    EAs = np.array([1e3, 1e4, 1e5])
    kw = dict(solver="kvaerno3", rtol=1e-6, atol=1e-6, n_save=11)
    base = _pendulum(formulation, EA=1e3, alpha=0.01)
    res = sweep(
        base, {"alpha": alphas, "EA": EAs}, _end_and_tension, mode="lockstep", **kw
    )
    assert res.mode == "lockstep" and res.ok.all(), res.status
    loop_err, lock_err, diff, steps = [], [], [], []
    for i, (a, ea) in enumerate(zip(alphas, EAs)):
        scene = _pendulum(formulation, EA=ea, alpha=a)
        traj = js.simulate(scene, **kw)
        ref = js.simulate(scene, solver="kvaerno5", rtol=1e-10, atol=1e-10, n_save=11)
        steps.append(int(traj.stats["num_steps"]))
        loop_err.append(np.max(np.abs(np.asarray(traj.end_mass - ref.end_mass))))
        lock_err.append(np.max(np.abs(res.out["end"][i] - np.asarray(ref.end_mass))))
        diff.append(np.max(np.abs(res.out["end"][i] - np.asarray(traj.end_mass))))
    # The members' problems differ: their own step counts differ.
    assert max(steps) > min(steps), steps
    # The shared sequence is at least as fine as the hardest member needs.
    assert int(res.stats["num_steps"][0]) >= 0.8 * max(steps)
    assert max(lock_err) <= 3 * max(loop_err), (lock_err, loop_err)
    assert max(lock_err) < 1e-4 and max(diff) < 1e-4  # 100 x rtol, 1 m string
    # Not the same numbers as the loop (a different step sequence) ...
    assert max(diff) > 1e-12
    # ... and the tension agrees to the same relative level.
    for i, (a, ea) in enumerate(zip(alphas, EAs)):
        scene = _pendulum(formulation, EA=ea, alpha=a)
        t_ref = float(jnp.max(js.simulate(scene, **kw).tension))
        assert abs(res.out["T_max"][i] - t_ref) < 1e-3 * t_ref


def test_lockstep_failure_falls_back_to_one_solve_per_member():
    base = js.string_pendulum(
        formulation="displacement", k=3, EA=1e3, alpha=0.02, t1=0.2
    )
    # Alone, the members need 101, 121 and 61 step attempts (simulate's defaults);
    # the shared step sequence of all three at least as many: with max_steps = 110
    # the shared solve fails, and only member 1 fails on its own.
    EAs = np.array([1e3, 2e3, 1e11])
    res = sweep(
        base,
        {"EA": EAs},
        _end_and_tension,
        devices=1,
        max_steps=110,
        mode="lockstep",
        **KW,
    )
    assert res.mode == "lockstep, then vmap"
    assert res.ok.tolist() == [True, False, True], res.status
    for i in (0, 2):
        scene = js.string_pendulum(
            formulation="displacement", k=3, EA=EAs[i], alpha=0.02, t1=0.2
        )
        ref = js.simulate(scene, max_steps=110, **KW)
        assert ref.ok
        assert np.max(np.abs(res.out["end"][i] - np.asarray(ref.end_mass))) < 1e-10


@pytest.mark.parametrize(
    "linear_solver",
    [pytest.param("batched_dense", marks=pytest.mark.slow), "batched_banded"],
)
def test_batched_factor_equals_per_member_dense_solves(linear_solver):
    # A stacked residual of independent members, each a Newton matrix
    # I - h J(member) of a string (node-major, block-tridiagonal Jacobian):
    # the batched factor must solve every member's own dense system.
    scenes = [
        js.string_pendulum(k=k_, EA=ea, alpha=a)
        for k_, ea, a in [(12, 1e4, 0.01), (12, 1e6, 0.0), (12, 1e5, 0.05)]
    ]
    rng = np.random.default_rng(0)
    ys = jnp.stack([s.y0 + 0.01 * rng.standard_normal(s.y0.shape) for s in scenes])
    h = 1e-3
    eas = jnp.array([float(s.model.EA) for s in scenes])
    al = jnp.array([float(s.effects[1].alpha) for s in scenes])
    base = scenes[0]

    def member_vf(y, ea, a):
        sc = eqx.tree_at(lambda s: (s.model.EA, s.effects[1].alpha), base, (ea, a))
        return sc.vector_field(0.0, y)

    def residual(u, args):
        eas, al = args
        return u - h * jax.vmap(member_vf)(u, eas, al)

    fac = jax.jit(lambda y, a: batched_factor(residual, y, a, linear_solver))(
        ys, (eas, al)
    )
    rhs = jnp.asarray(rng.standard_normal(ys.shape))
    x = fac.solve(rhs)
    width = None if linear_solver == "batched_dense" else 1

    def own(u, i):
        return residual(ys.at[i].set(u), (eas, al))[i]

    member_jacobian = jax.jit(jax.jacfwd(own))
    single_solve = jax.jit(
        lambda u, r, i: _linalg.factor(
            _linalg.jacobian(lambda v: own(v, i), u, width)
        ).solve(r)
    )
    for i in range(len(scenes)):
        J = np.asarray(member_jacobian(ys[i], i)).reshape(ys[i].size, ys[i].size)
        xi = np.asarray(x[i]).ravel()
        b = np.asarray(rhs[i]).ravel()
        # Backward stable: residual at rounding level of |J| |x|.
        backward = np.max(np.abs(J @ xi - b)) / np.max(np.abs(J) @ np.abs(xi))
        assert backward < 1e-14, backward
        # Forward error: the single-member path of the same structure and a dense
        # LU agree to the conditioning of J (I - h J of a stiff string).
        bound = 1e-15 * np.linalg.cond(J) * np.max(np.abs(xi))
        single = single_solve(ys[i], rhs[i], i)
        assert np.max(np.abs(np.asarray(single).ravel() - xi)) <= bound
        assert np.max(np.abs(np.linalg.solve(J, b) - xi)) <= bound


def test_member_rms_max_is_the_largest_member_rms():
    x = jnp.array([[3.0, 4.0], [1.0, 1.0], [0.0, 0.0]])
    assert float(member_rms_max(x)) == pytest.approx(np.sqrt(12.5), rel=1e-15)


@pytest.mark.parametrize(
    "solver",
    [
        pytest.param("implicit_euler_fixed", marks=pytest.mark.slow),
        pytest.param("trapezoid", marks=pytest.mark.slow),
    ],
)
def test_fixed_step_lockstep_equals_the_loop_to_rounding(solver):
    # With a fixed step every member takes the same steps alone and in the sweep;
    # the lockstep group (members' nodes concatenated into one banded system)
    # then differs from the loop only by how far each step's Newton iteration is
    # converged: with a Newton tolerance of 1e-10 (quadratic convergence), to
    # rounding. Members of different stiffness and damping; groups of 2 over 3
    # members (a padded group), and the vmap mode, give the same numbers.
    base = js.string_pendulum(
        formulation="displacement", k=4, EA=1e4, alpha=0.01, t1=0.3
    )
    alphas = np.array([0.0, 0.01, 0.05])
    EAs = np.array([1e3, 1e4, 1e6])
    kw = dict(solver=solver, dt0=0.01, newton_rtol=1e-10, newton_atol=1e-10, n_save=11)
    values = {"alpha": alphas, "EA": EAs}
    runs = [
        sweep(base, values, _end_and_tension, devices=1, mode="lockstep", **kw),
        sweep(
            base,
            values,
            _end_and_tension,
            devices=1,
            mode="lockstep",
            batch_size=2,
            **kw,
        ),
        sweep(base, values, _end_and_tension, devices=1, **kw),
    ]
    for res in runs:
        assert res.ok.all(), res.status
    assert runs[0].mode == "lockstep"
    for i, (a, ea) in enumerate(zip(alphas, EAs)):
        scene = js.string_pendulum(
            formulation="displacement", k=4, EA=ea, alpha=a, t1=0.3
        )
        traj = js.simulate(scene, **kw)
        ref = _end_and_tension(traj, scene)
        for res in runs:
            assert int(res.stats["num_steps"][i]) == int(traj.stats["num_steps"])
            assert np.max(np.abs(res.out["end"][i] - np.asarray(ref["end"]))) < 1e-10
            t_ref = float(ref["T_max"])
            assert abs(res.out["T_max"][i] - t_ref) < 1e-10 * t_ref
    # The members differ (the sweep is not one member repeated).
    assert np.ptp(runs[0].out["T_max"]) > 1e-3 * np.max(runs[0].out["T_max"])


def test_lockstep_rejects_what_it_cannot_do():
    base = _pendulum(EA=1e3, alpha=0.01)
    with pytest.raises(ValueError, match="mode"):
        sweep(base, {"alpha": [0.01]}, mode="fast")
    with pytest.raises(ValueError, match="solver"):
        sweep(base, {"alpha": [0.01]}, mode="lockstep", solver="rodas5p")
    with pytest.raises(ValueError, match="time span"):
        sweep(base, {"t1": [0.2, 0.3]}, mode="lockstep")
    with pytest.raises(ValueError, match="solver"):
        sweep(base, {"alpha": [0.01]}, mode="lockstep", solver="newmark")
