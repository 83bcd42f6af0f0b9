"""The simplified Newton iteration the implicit solvers share
(`jaxstring._solvers.newton`): its root, its rate and its stopping test against
the analytic contraction of a chord iteration on scalar equations."""

import math

import jax.numpy as jnp
import numpy as np

from jaxstring._solvers.newton import chord, contraction_test


ROOT = 0.7390851332151607  # x = cos x (the Dottie number)


def _size(x, dx, x_new):
    return jnp.abs(dx) / 1e-12


def test_chord_finds_the_root_at_the_analytic_rate():
    """r(x) = x - cos x with the slope at x0 = 0 (1): the chord iteration
    contracts at |1 - r'(x*) / r'(0)| = sin x* = 0.674 and stops where the
    estimated distance rate / (1 - rate) |dx| is below tol (here 1e-12 absolute)
    -- so the root is within about 1e-12, reached in about
    log(1e-12) / log(0.674) = 70 updates."""
    x, ok, n = chord(lambda x: x - jnp.cos(x), lambda r: r, jnp.array(0.0),
                     _size, 1.0, 200)  # fmt: skip
    assert bool(ok)
    assert abs(float(x) - ROOT) < 3e-12
    rate = math.sin(ROOT)
    expected = math.log(1e-12) / math.log(rate)
    assert abs(int(n) - expected) < 8


def test_linear_equation_converges_after_one_exact_update():
    """With the exact slope of a linear equation the first update lands on the
    root; the second is zero and ends the iteration."""
    x, ok, n = chord(lambda x: 3.0 * x - 6.0, lambda r: r / 3.0, jnp.array(10.0),
                     _size, 1.0, 10)  # fmt: skip
    assert bool(ok) and int(n) == 2 and float(x) == 2.0


def test_divergence_is_declared_early():
    """A slope one tenth of the true one overshoots: the update grows ninefold
    each time (rate 9 >= 1), so the iteration stops as diverged after its second
    update, keeping that (finite) iterate."""
    x, ok, n = chord(lambda x: x, lambda r: 10.0 * r, jnp.array(1.0),
                     _size, 1.0, 50)  # fmt: skip
    assert not bool(ok) and int(n) == 2
    assert float(x) == 81.0


def test_prediction_gives_up_when_the_horizon_is_too_short():
    """Contracting at 0.9 from an update of 1e3 (scaled), the predicted size
    after the remaining updates, 0.9^(h - k - 1) / 0.1 * size, is far above the
    tolerance for a horizon of 4: too slow, while without a horizon the same
    update is only 'not yet converged'."""
    size, prev = jnp.array(900.0), jnp.array(1000.0)
    conv, slow, rate = contraction_test(size, prev, 1, 1.0, 4)
    assert not bool(conv) and bool(slow)
    np.testing.assert_allclose(float(rate), 0.9)
    conv, slow, _ = contraction_test(size, prev, 1, 1.0, None)
    assert not bool(conv) and not bool(slow)
    # a negligible first update converges only where a first tolerance is given
    tiny = jnp.array(1e-4)
    assert bool(contraction_test(tiny, jnp.inf, 0, 1.0, 4, first_tol=1e-3)[0])
    assert not bool(contraction_test(tiny, jnp.inf, 0, 1.0, 4)[0])
