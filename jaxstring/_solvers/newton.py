"""The simplified Newton iteration the implicit solvers share.

BDF, the written-out ESDIRK and the fixed-step methods solve their implicit
equation r(x) = 0 by the same iteration: x <- x - J0^{-1} r(x) with one stored
factorisation J0 of the Jacobian (a "chord" iteration), stopped by Hairer &
Wanner's test (*Solving ODEs II*, section IV.8), which `StageNewton` applies too:

* the rate theta_k = |dx_k| / |dx_(k-1)| estimates the contraction;
* converged when theta / (1 - theta) |dx| <= tol (the estimated distance to the
  root), or the update is already negligible;
* diverged when theta >= 1, or when the predicted size after the iterations
  still allowed, theta^(n - k - 1) / (1 - theta) |dx|, is above tol -- the step is
  then rejected (or the Jacobian refreshed) early instead of iterating in vain.

|dx| is a scaled RMS size that each solver defines in the units of its state.
"""

import jax.lax as lax
import jax.numpy as jnp


def contraction_test(size, prev, it, tol, horizon, first_tol=None, tiny=0.0):
    """Hairer & Wanner's test after update `it` (0-based) of scaled size `size`,
    the update before it of size `prev` (inf before the first).

    Returns (converged, too_slow, rate):

    - `converged`: `size <= tiny`; on the first update `size <= first_tol` (no
      rate yet; never, with `first_tol` None); later `rate < 1` and
      `rate / (1 - rate) * size <= tol`;
    - `too_slow`: after the first update, `rate >= 1` or the prediction
      `rate ** (horizon - it - 1) / (1 - rate) * size > tol` (`horizon`: the
      number of updates the prediction allows; None: no prediction);
    - `rate`: `size / prev`.
    """
    rate = size / prev
    first = it == 0
    later = (rate < 1) & (rate / (1 - rate) * size <= tol)
    if first_tol is None:
        converged = ~first & later
    else:
        converged = jnp.where(first, size <= first_tol, later)
    converged = converged | (size <= tiny)
    slow = rate >= 1
    if horizon is not None:
        remaining = jnp.maximum(horizon - it - 1, 0)
        slow = slow | (rate**remaining / (1 - rate) * size > tol)
    return converged, ~first & slow, rate


def chord(
    residual,
    solve,
    x0,
    size_of,
    tol,
    max_iters,
    horizon=None,
    first_tol=None,
    tiny=0.0,
):
    """The simplified Newton iteration x <- x - solve(residual(x)) from `x0`.

    - `solve(r)`: the stored factorisation's solve (a chord correction may be
      folded in);
    - `size_of(x, dx, x_new)`: the scaled size of the update dx from x to
      x_new = x - dx;
    - `tol`, `horizon`, `first_tol`, `tiny`: `contraction_test`'s;
    - `max_iters`: the most updates.

    A non-finite update is not applied and ends the iteration as diverged; a
    finite one is applied even when the test then finds the iteration diverging
    (a retry may start from it). Returns (x, converged, updates made).
    """
    dtype = jnp.result_type(x0)

    def cond(carry):
        it, _, _, converged, failed = carry
        return (it < max_iters) & ~converged & ~failed

    def body(carry):
        it, x, prev, _, _ = carry
        dx = solve(residual(x))
        x_new = x - dx
        size = size_of(x, dx, x_new)
        finite = jnp.isfinite(size)
        converged, slow, _ = contraction_test(
            size, prev, it, tol, horizon, first_tol, tiny
        )
        failed = ~finite | slow
        x = jnp.where(finite, x_new, x)
        return it + 1, x, size, converged & ~failed, failed

    init = (
        jnp.array(0, jnp.int32),
        x0,
        jnp.array(jnp.inf, dtype),
        jnp.array(False),
        jnp.array(False),
    )
    it, x, _, converged, _ = lax.while_loop(cond, body, init)
    return x, converged, it
