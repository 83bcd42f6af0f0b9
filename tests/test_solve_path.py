"""One solve path: simulate, fit (its loss and gradient) and sweep integrate a scene
through the same `solve`, so they give the same trajectory; a solve placed on a
named device runs there with the same result."""

import pathlib
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js

from .helpers import run_on_two_cpu_devices


def test_simulate_fit_and_sweep_give_the_same_trajectory():
    scene = js.pendulum.string_pendulum(k=5, EA=1e4, alpha=0.02, t1=0.3)
    ts = jnp.linspace(0.0, 0.3, 7)
    kw = dict(solver="kvaerno5", rtol=1e-8, atol=1e-8, ts=ts)
    end = np.asarray(js.simulate(scene, **kw).end_mass)
    assert np.ptp(end[:, 1]) > 0.05  # it really moves

    swept = js.sweep(
        scene, {"alpha": jnp.array([0.02])}, lambda tr, s: tr.end_mass, **kw
    )
    assert bool(swept.ok.all())
    np.testing.assert_allclose(np.asarray(swept.out)[0], end, rtol=0, atol=1e-12)

    # fit's objective: the loss it descends is evaluated on the same trajectory.
    weights = jnp.arange(end.size, dtype=jnp.float64).reshape(end.shape)
    loss = lambda tr, s: jnp.sum(weights * tr.end_mass)
    value, _ = js.value_and_grad(scene, loss, ["alpha"], **kw)
    assert abs(value - float(np.sum(np.asarray(weights) * end))) < 1e-12 * max(
        1.0, abs(value)
    )


def test_a_solve_traces_the_vector_field_once(monkeypatch):
    # diffrax traces its step loop's body up to three times per solve, and a step
    # evaluates the vector field in many places (stages, Jacobians, error
    # estimate): the scene's vector field is traced once per structure, then reused
    # by every solver. (k = 13: a structure no other test of the suite solves.)
    from jaxstring import _scene

    calls = []
    vector_field = _scene.Scene.vector_field

    def counting(self, t, y):
        calls.append(t)
        return vector_field(self, t, y)

    monkeypatch.setattr(_scene.Scene, "vector_field", counting)
    scene = js.pendulum.string_pendulum(k=13, t1=0.01)
    first = js.simulate(scene, "bdf", n_save=2)
    assert first.ok and len(calls) == 1
    second = js.simulate(scene, "implicit_euler", n_save=2)
    assert second.ok and len(calls) == 1
    np.testing.assert_allclose(
        np.asarray(second.ys[-1]), np.asarray(first.ys[-1]), rtol=0, atol=1e-4
    )


def test_a_named_device_moves_the_arrays_and_keeps_the_functions():
    # A solve's arguments hold functions (a residual) beside arrays: placing them
    # on a named device moves the arrays and leaves the rest as it was.
    cpu = jax.devices("cpu")[0]

    def residual(traj, scene):
        return traj.end_mass

    tree = (jnp.arange(3.0), residual, {"n": 4, "x": np.ones(2)})
    placed = js.SolveConfig(device=cpu).placed(tree)
    assert placed[1] is residual and placed[2]["n"] == 4
    assert placed[0].devices() == {cpu} and placed[0].committed
    assert np.array_equal(placed[0], tree[0])
    assert np.array_equal(placed[2]["x"], tree[2]["x"])
    assert js.SolveConfig().placed(tree) is tree  # "auto" on a CPU host


@pytest.mark.slow
def test_solves_on_a_named_second_device_equal_those_on_the_first():
    # A fresh process with two CPU devices: simulate and least_squares with
    # `device=` the second run there and give the first device's results.
    code = textwrap.dedent(
        """
        import numpy as np, jax, jax.numpy as jnp
        import jaxstring as js
        second = jax.devices()[1]
        scene = js.string_pendulum(k=3, EA=1e3, alpha=0.02, t1=0.2)
        ts = jnp.linspace(0.0, 0.2, 11)
        one = js.simulate(scene, ts=ts)
        two = js.simulate(scene, ts=ts, device=second)
        assert two.end_mass.devices() == {second}, two.end_mass.devices()
        data = np.asarray(one.end_mass)  # on the host: no device of its own
        start = js.string_pendulum(k=3, EA=1e3, alpha=0.03, t1=0.2)
        res = lambda t, s: t.end_mass - data
        fits = [js.least_squares(start, res, ["alpha"], ts=ts, device=d)
                for d in ("auto", second)]
        print(float(np.max(np.abs(data - np.asarray(two.end_mass)))),
              abs(fits[0].values["alpha"] - fits[1].values["alpha"]),
              fits[1].values["alpha"])
        """
    )
    ends, fits, alpha = map(float, run_on_two_cpu_devices(code).split())
    assert ends < 1e-12 and fits < 1e-12
    assert abs(alpha - 0.02) < 1e-6  # the fit finds the damping of the data


def test_saved_program_keys_follow_every_static_value():
    """The in-process memo of saved-program keys gives the key of the full
    computation, and a different key whenever a static value (or its type)
    differs."""
    import equinox as eqx
    import jax.tree_util as jtu

    from jaxstring import _integrate, _programs

    def key(scene, **options):
        config = js.SolveConfig(**options)
        dynamic, static = eqx.partition((scene, config), eqx.is_array)
        leaves, treedef = jtu.tree_flatten(dynamic)
        fn = _integrate._solve_fields
        memo, arrays = _programs._key(fn, (scene, config))
        assert all(a is b for a, b in zip(arrays, leaves, strict=True))
        assert memo == _programs._full_key(fn, static, treedef, leaves)
        return memo

    scene = js.string_pendulum(k=4)
    base = key(scene, solver="tsit5")
    assert key(scene, solver="tsit5") == base
    assert key(scene, solver="tsit5", rtol=1e-3) == base  # rtol is an array leaf
    assert key(scene, solver="dopri5") != base
    assert key(scene, solver="tsit5", n_save=11) != base
    assert key(js.string_pendulum(k=5), solver="tsit5") != base
    one = key(scene, solver="tsit5", max_steps=1000)
    assert key(scene, solver="tsit5", max_steps=1001) != one


def test_the_unchecked_replacements_of_a_solve_give_the_checked_configuration():
    """`simulate` replaces the save count and times of a checked configuration
    without checking them again: the same configuration, the same saved-program
    key, and the cached defaults are the defaults."""
    import equinox as eqx
    import jax.tree_util as jtu

    from jaxstring import _integrate, _programs

    scene = js.string_pendulum(k=4)
    config = js.SolveConfig(solver="tsit5", rtol=1e-3, ts=np.linspace(0.0, 1.0, 5))

    def key(c):
        dynamic, static = eqx.partition((scene, c), eqx.is_array)
        leaves, treedef = jtu.tree_flatten(dynamic)
        return _programs._full_key(_integrate._solve_fields, static, treedef, leaves)

    for fields in ({"n_save": 32}, {"ts": None}, {"ts": None, "n_save": 8}):
        fast, checked = config.replace_unchecked(**fields), config.replace(**fields)
        assert type(fast) is type(checked)
        assert eqx.tree_equal(fast, checked)
        assert key(fast) == key(checked)
    assert key(config.replace_unchecked(n_save=32)) != key(config)
    for purpose in ("simulate", "identify", "sweep"):
        assert eqx.tree_equal(
            js.SolveConfig.default(purpose),
            js.SolveConfig(
                **(js.SOLVE_DEFAULTS["simulate"] | js.SOLVE_DEFAULTS[purpose])
            ),
        )


@pytest.mark.parametrize("solver", ["kvaerno5", "bdf"])
def test_a_solve_nothing_differentiates_gives_the_same_values_from_a_smaller_trace(
    solver,
):
    # simulate on concrete arrays (and a sweep's members) integrate with
    # `differentiable=False`: diffrax's plain loops and no custom_root around the
    # Newton solves, whose derivative rule JAX traces with every solve. The same
    # steps and values as the solve that gradients go through.
    from jaxstring import _integrate

    scene = js.string_pendulum(formulation="natural", k=4, EA=1e4, t1=0.2)
    config = js.SolveConfig(solver=solver, rtol=1e-6, atol=1e-6)
    ts = jnp.linspace(0.0, 0.2, 5)
    both = [_integrate.jit_solve(scene, config, ts)]  # the one gradients take
    both.append(_integrate.jit_solve_values(scene, config, ts))
    programs = [
        str(jax.make_jaxpr(lambda sc, d=d: _integrate.solve(sc, config, ts,
                                                            differentiable=d).ys)(scene))
        for d in (True, False)
    ]  # fmt: skip
    assert "custom_root" in programs[0] and "custom_root" not in programs[1]
    assert int(both[0].stats["num_steps"]) == int(both[1].stats["num_steps"]) > 5
    np.testing.assert_array_equal(np.asarray(both[1].ys), np.asarray(both[0].ys))
    # and simulate on concrete arrays (save times padded to 8: the same steps)
    np.testing.assert_allclose(
        np.asarray(js.simulate(scene, config=config, ts=ts).ys),
        np.asarray(both[1].ys),
        rtol=0,
        atol=1e-12,
    )


def test_a_cut_through_the_host_and_a_compiled_cut_give_the_same_trajectory(
    monkeypatch,
):
    """Save times padded to the program's count are cut back on the host at
    first and by a compiled program once the same cut has come often enough:
    the same rows, the same valid count."""
    import jax.tree_util as jtu

    from jaxstring import _integrate

    monkeypatch.setattr(_integrate, "CUT_COMPILED_AFTER", 1)
    monkeypatch.setattr(_integrate, "_HOST_CUTS", {})
    scene = js.string_pendulum(k=3, t1=0.2)
    ts = np.linspace(0.0, 0.2, 5)  # padded to 8 in the program
    host, compiled = (js.simulate(scene, "tsit5", ts=ts) for _ in range(2))
    # one cut on the host, the second compiled
    assert list(_integrate._HOST_CUTS.values()) == [1] and host.ts.shape == (5,)
    assert int(host.n_valid) == int(compiled.n_valid) == 5
    for a, b in zip(jtu.tree_leaves(host), jtu.tree_leaves(compiled), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    np.testing.assert_array_equal(np.asarray(compiled.ts), ts)


@pytest.mark.parametrize(
    "after, segments", [("time", 23), ("calls", 29)], ids=["time", "calls"]
)
def test_a_run_once_program_compiled_quickly_then_optimised_gives_the_same_state(
    monkeypatch, tmp_path, after, segments
):
    """A deck's static equilibrium (a program run once per structure, mostly) is
    compiled at XLA's optimisation level 0 first and with full optimisation once
    its runs add up or it has come often enough (here at its second call): both
    give the same state at rest, to rounding, with the same residual force and
    fairlead tension."""
    import math

    from jaxstring import _jit

    used = {}  # per tiered program: which compilation served each call
    tiers_call = _jit.Tiers.__call__

    def spy(self, signature, quick, full, *args):
        tier = "full" if self.promoted(signature) else "quick"
        used.setdefault((id(self), signature), []).append(tier)
        return tiers_call(self, signature, quick, full, *args)

    monkeypatch.setattr(_jit.Tiers, "__call__", spy)
    if after == "time":
        monkeypatch.setattr(_jit, "PROMOTE_AFTER_S", 0.0)
    else:
        monkeypatch.setattr(_jit, "PROMOTE_AFTER_S", math.inf)
        monkeypatch.setattr(_jit, "PROMOTE_AFTER_CALLS", 2)
    # MoorDyn's WD0050 chain with fewer segments: a structure no other test compiles
    text = pathlib.Path(js.lines.case_path("WD0050_Chain.txt")).read_text()
    deck_file = tmp_path / "chain.txt"
    deck_file.write_text(text.replace("410       41", f"410       {segments}"))
    deck = js.lines.read_moordyn(deck_file)
    quick, info_q = js.lines.equilibrium(deck.model, deck.effects, deck.env)
    full, info_f = js.lines.equilibrium(deck.model, deck.effects, deck.env)
    # the read's solve (compiled), one more timed (then promoted), the optimised;
    # the same for the other run-once programs of the read and the two solves
    assert ["quick", "quick", "full"] in used.values()
    assert all(calls[2:] in ([], ["full"]) for calls in used.values())
    x = np.asarray(full)[:, :3]
    assert float(np.ptp(x[:, 0])) > 300.0 and float(x[:, 2].min()) < -49.0
    np.testing.assert_allclose(np.asarray(quick), np.asarray(full), rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(deck.y0), np.asarray(full), rtol=0, atol=1e-9)
    for info in (info_q, info_f):
        assert float(info["residual"]) < 1e-3  # N, of ~1e6 N tensions
    np.testing.assert_allclose(
        np.asarray(info_q["tension_a"]), np.asarray(info_f["tension_a"]), rtol=1e-10
    )


def test_a_gradient_through_simulate_with_save_times_cut_back_matches_differences():
    """Five save times run the program of eight, cut back after the solve; under
    `jax.grad` and `jax.jit` the cut is traced with the caller's program (a
    compiled cut there would be a nested jit): the derivative of the end mass's
    last height with respect to the axial stiffness agrees with central
    differences."""
    import equinox as eqx

    scene = js.string_pendulum(k=3, EA=1e3, alpha=0.05, t1=0.3)
    ts = jnp.linspace(0.0, 0.3, 5)

    def height(EA):
        s = eqx.tree_at(lambda s: s.model.EA, scene, EA)
        traj = js.simulate(s, "kvaerno5", rtol=1e-11, atol=1e-11, ts=ts)
        assert traj.ts.shape == (5,)
        return traj.end_mass[-1, 1]

    EA = jnp.asarray(1e3)
    grad = float(jax.grad(height)(EA))
    assert float(jax.jit(jax.grad(height))(EA)) == pytest.approx(grad, rel=1e-9)
    h = 1.0
    fd = (float(height(EA + h)) - float(height(EA - h))) / (2 * h)
    assert abs(fd) * float(EA) > 5e-5  # m per relative change: EA moves the mass
    assert grad == pytest.approx(fd, rel=1e-5)
