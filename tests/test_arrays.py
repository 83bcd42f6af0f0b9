"""Static index arrays as slices (`_arrays.take_rows`, `add_rows`): equal to the
gather and the scatter they replace for every pattern of rows, a single line's
vector field free of gathers and scatters, and a network's free of scatters."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxstring import _arrays, lines


PATTERNS = [
    np.arange(6),  # one run
    np.array([3, 0, 1, 2, 3, 3, 4]),  # a network's node -> slot map
    np.array([1, 2, 3, 4, 5, 5]),  # `next` of a line (its end repeated)
    np.array([0, 0, 1, 2, 3]),  # `prev`
    np.array([2, 2, 2, 2]),  # one repeated row (a line's parameter per segment)
    np.array([5, 4, 3, 1]),  # descending
    np.array([6, 4, 2, 0, 1, 4]),  # strided runs (a state ordered for a narrow band)
    np.random.default_rng(0).integers(0, 7, size=40),  # many runs
]


@pytest.mark.parametrize("max_runs", [4, 64])
@pytest.mark.parametrize("idx", PATTERNS)
def test_take_and_add_rows_equal_the_gather_and_the_scatter(idx, max_runs, monkeypatch):
    monkeypatch.setattr(_arrays, "MAX_RUNS", max_runs)  # slices, or a gather
    rng = np.random.default_rng(1)
    x = rng.normal(size=(7, 3))
    np.testing.assert_array_equal(_arrays.take_rows(jnp.asarray(x), idx), x[idx])
    v = rng.normal(size=(idx.size, 3, 2))
    ref = np.zeros((7, 3, 2))
    np.add.at(ref, idx, v)
    np.testing.assert_allclose(_arrays.add_rows(7, idx, jnp.asarray(v)), ref,
                               rtol=1e-15, atol=1e-15)  # fmt: skip
    # forward-mode derivatives (the banded Jacobians' JVPs) are the same maps
    t = rng.normal(size=x.shape)
    _, dx = jax.jvp(lambda a: _arrays.take_rows(a, idx), (jnp.asarray(x),),
                    (jnp.asarray(t),))  # fmt: skip
    np.testing.assert_array_equal(dx, t[idx])


def _primitives(jaxpr, out):
    for e in jaxpr.eqns:
        out.add(e.primitive.name)
        for sub in jax.extend.core.jaxprs_in_params(e.params):
            _primitives(sub, out)
    return out


def test_a_single_lines_vector_field_has_no_gather_or_scatter():
    """MoorDyn's WD0050 and WD0200 chains: every index array of the topology is
    a few runs of rows."""
    for deck in ("WD0050_Chain.txt", "WD0200_Chain.txt"):
        scene = lines.deck_scene(lines.parse_moordyn(lines.case_path(deck)),
                                 static=False)  # fmt: skip
        jaxpr = jax.make_jaxpr(lambda y: scene.vector_field(0.0, y))(scene.y0)
        found = _primitives(jaxpr.jaxpr, set())
        assert not found & {"gather", "scatter", "scatter-add", "scatter_add"}, deck


def test_a_networks_vector_field_sums_rows_without_a_scatter():
    """MoorDyn's tripod (11 lines) and BodiesAndRods (6 lines and a body): index
    arrays of more runs than `MAX_RUNS` are gathers, and the sums into rows
    gathers of the inverse index, never scatters (XLA:CPU's loops of one dynamic
    update per row)."""
    for deck in ("tripod.txt", "BodiesAndRods.dat"):
        scene = lines.read_moordyn(lines.case_path(deck), static=False)
        jaxpr = jax.make_jaxpr(lambda y: scene.vector_field(0.0, y))(scene.y0)
        found = _primitives(jaxpr.jaxpr, set())
        assert "gather" in found, deck
        assert not found & {"scatter", "scatter-add", "scatter_add"}, deck


def _compilations(fn):
    """(fn(), how many programs JAX compiled while it ran)."""
    seen = []

    def listen(event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            seen.append(duration)

    jax.monitoring.register_event_duration_secs_listener(listen)
    try:
        out = fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listen)
    return out, len(seen)


@pytest.mark.parametrize(
    "value",
    [0.3, 7, [1.0, 2.5, -3.0], np.arange(4), np.float32(1.5),
     np.ones((2, 3), np.float32), True],
)  # fmt: skip
def test_host_values_become_float64_arrays_without_compiling(value):
    # `f64` (every parameter field's converter) and `as_array` convert host values
    # with NumPy and move them in one transfer: the same values as
    # `jnp.asarray(..., float64)`, and no conversion program compiled.
    out, compiled = _compilations(lambda: _arrays.f64(value))
    assert compiled == 0
    assert isinstance(out, jax.Array) and out.dtype == jnp.float64
    np.testing.assert_array_equal(out, np.asarray(value, np.float64))
    kept, compiled = _compilations(lambda: _arrays.as_array(value))
    assert compiled == 0
    np.testing.assert_array_equal(kept, np.asarray(value))
    assert kept.dtype == jnp.asarray(value).dtype


def test_float64_arrays_and_tracers_pass_through():
    x = jnp.linspace(0.0, 1.0, 5)
    assert _arrays.f64(x) is x
    # inside a trace the conversion is JAX's own
    y = jax.jit(lambda v: _arrays.f64(v.astype(jnp.float32)) * 2.0)(x)
    np.testing.assert_allclose(y, 2.0 * np.asarray(x, np.float32), rtol=0)
    # not numbers: JAX's own error, as before
    with pytest.raises(ValueError):
        jnp.asarray("not a number", dtype=jnp.float64)
    with pytest.raises(ValueError):
        _arrays.f64("not a number")
