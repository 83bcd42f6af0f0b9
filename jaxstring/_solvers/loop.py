"""The step loop of a solve that reverse mode does not differentiate.

`diffrax.diffeqsolve` serves every use of a solver: events, dense output, saving
every step, a progress meter, time running backwards, jumps in the vector field, and
reverse-mode gradients through its checkpointed loops. A forward solve saved at
given times needs none of it, yet its program holds all of it: equinox's rewritten
while loops (a select per carried array and per buffer), the 100 calls that put
`t1` less 100 units in the last place, the loop body traced once more to find which
of its values stay static. `solve` below runs the same step, controller, clipping
and saving as diffrax's loop, in the same order, with one `lax.while_loop` over the
steps and one over a step's save times: the same values to the last bit (the
tests compare them with `diffeqsolve`'s), from a program about a third smaller to
trace and to compile (measured: docs/performance.md, "A step loop of its own").

It serves solves whose times run forward (t1 > t0, as every jaxstring solve),
saved at given times, by a solver and controller whose steps never jump
(`PIDController`, `ConstantStepSize`, jaxstring's
`NewtonLimitedController`), under forward-mode derivatives or none. Under `vmap`
(a sweep's members, `batched`) the loops are equinox's (`equinox.internal.while_loop`
with the saved rows as its buffer), as diffrax's forward mode runs them: there a
plain while loop selects every carried array whole at every step, the saved rows
included, where equinox's writes one row (measured: the same page).
"""

from typing import Any, NamedTuple

import diffrax as dfx
import equinox as eqx
import equinox.internal as eqxi
import jax
import jax.lax as lax
import jax.numpy as jnp
import jax.tree_util as jtu

from .diffrax_compat import forward_term, takes_controller_tolerances
from .step_size import NewtonLimitedController


class Solution(NamedTuple):
    """The parts of diffrax's `Solution` that a jaxstring solve reads."""

    ys: Any
    result: Any
    stats: dict


_CONTROLLERS = (dfx.PIDController, dfx.ConstantStepSize, NewtonLimitedController)


def serves(solver, controller, adjoint, progress, saveat) -> bool:
    """Whether `solve` serves a `diffeqsolve` of `solver` under `controller`,
    `adjoint` and `saveat`, with the progress meter on or off."""
    if progress or not isinstance(adjoint, dfx.ForwardMode):
        return False
    if type(controller) not in _CONTROLLERS:
        return False
    sub = saveat.subs
    if not isinstance(sub, dfx.SubSaveAt) or saveat.dense:
        return False
    if sub.ts is None or sub.t0 or sub.t1 or sub.steps:
        return False
    # an implicit solver whose root finder takes the controller's tolerances
    # (diffrax's default Kvaerno): diffeqsolve sets them
    inner = solver.solver if isinstance(solver, dfx.AbstractWrappedSolver) else solver
    return not takes_controller_tolerances(inner)


def _plain_stages(solver):
    """`solver` with the stages of a Runge-Kutta method (a wrapped one's: a
    projection) in a plain scan, as diffrax's forward mode runs them (its
    checkpointed scan has a custom_vjp, which forward mode cannot go through)."""
    if isinstance(solver, dfx.AbstractWrappedSolver):
        inner = _plain_stages(solver.solver)
        return eqx.tree_at(lambda s: s.solver, solver, inner)
    if isinstance(solver, dfx.AbstractRungeKutta) and solver.scan_kind is None:
        return eqx.tree_at(
            lambda s: s.scan_kind, solver, "lax", is_leaf=lambda x: x is None
        )
    return solver


def _less_100_ulp(t1):
    """`t1` less 100 units in the last place, as diffrax's loop computes the time
    beyond which a step's end is moved to `t1`, in one loop."""

    def down(_, x):
        y = lax.nextafter(x, jnp.full_like(x, -jnp.inf))
        return jnp.where(x == 0, -jnp.finfo(x.dtype).tiny, y)

    return lax.fori_loop(0, 100, down, lax.stop_gradient(t1))


def _clip_to_end(tprev, tnext, t1, t1_clip_floor, keep_step):
    clip = tnext > t1_clip_floor
    tclip = jnp.where(keep_step, t1, tprev + 0.5 * (t1 - tprev))
    return jnp.where(clip, tclip, tnext)


class _State(eqx.Module):
    tprev: Any
    tnext: Any
    y: Any
    solver_state: Any
    controller_state: Any
    result: Any
    num_steps: Any
    num_accepted_steps: Any
    num_rejected_steps: Any
    save_index: Any
    ys: Any


def _while(cond, body, init, buffers, batched):
    """`lax.while_loop`; under `vmap` (`batched`) equinox's, with `buffers(init)`
    written a row at a time."""
    if not batched:
        return lax.while_loop(cond, body, init)
    return eqxi.while_loop(cond, body, init, buffers=buffers, kind="lax")


def solve(
    vector_field,
    y0,
    args,
    t0,
    t1,
    *,
    solver,
    controller,
    dt0,
    ts,
    fn,
    max_steps,
    batched=False,
) -> Solution:
    """Integrate dy/dt = `vector_field(t, y, args)` from `y0` over [t0, t1] and
    save `fn(t, y, args)` (None: y) at the increasing times `ts` in [t0, t1], as
    `diffeqsolve(..., saveat=SaveAt(ts=ts, fn=fn), adjoint=ForwardMode(),
    throw=False)` does. Saved rows not reached (a failed solve) are inf.
    `batched`: traced under `vmap` (the loops are then equinox's)."""
    if fn is None:
        fn = lambda t, y, args: y
    # wrapped for the direction of time, as diffeqsolve does (a solver may take
    # its own path for a wrapped term: diffrax's Runge-Kutta initial state)
    terms = forward_term(dfx.ODETerm(vector_field))
    dtype = jnp.result_type(t0, t1, float)
    t0 = jnp.asarray(t0, dtype)
    t1 = jnp.asarray(t1, dtype)
    ts = jnp.asarray(ts, dtype)
    if dt0 is not None:
        dt0 = jnp.asarray(dt0, dtype)
    controller = controller.wrap(1)
    solver = _plain_stages(solver)
    error_order = solver.error_order(terms)
    tnext, controller_state = controller.init(
        terms, t0, t1, y0, dt0, args, solver.func, error_order
    )
    tnext = jnp.minimum(tnext, t1)
    solver_state = solver.init(terms, t0, tnext, y0, args)
    n = ts.shape[0]
    struct = jax.eval_shape(fn, t0, y0, args)
    ys = jtu.tree_map(lambda s: jnp.full((n,) + s.shape, jnp.inf, s.dtype), struct)
    floor = _less_100_ulp(t1)
    zero = jnp.asarray(0)
    init = _State(
        t0, tnext, y0, solver_state, controller_state, dfx.RESULTS.successful,
        zero, zero, zero, zero, ys,
    )  # fmt: skip

    def going(s):
        return (s.tprev < t1) & dfx.is_successful(s.result)

    def cond(s):
        out = going(s)
        return out if max_steps is None else out & (s.num_steps < max_steps)

    def body(s):
        y, y_error, dense_info, solver_state, solver_result = solver.step(
            terms, s.tprev, s.tnext, s.y, args, s.solver_state, False
        )
        y_error = jtu.tree_map(lambda x: jnp.where(jnp.isnan(x), jnp.inf, x), y_error)
        keep_step, tprev, tnext, made_jump, controller_state, controller_result = (
            controller.adapt_step_size(
                s.tprev, s.tnext, s.y, y, args, y_error, error_order,
                s.controller_state,
            )
        )  # fmt: skip
        if made_jump is not False:
            raise AssertionError("a controller that jumps is diffeqsolve's")
        tprev = jnp.minimum(tprev, t1)
        tnext = _clip_to_end(tprev, tnext, t1, floor, keep_step)
        keep = lambda a, b: jnp.where(keep_step, a, b)
        y = jtu.tree_map(keep, y, s.y)
        solver_state = jtu.tree_map(keep, solver_state, s.solver_state)
        solver_result = dfx.RESULTS.where(
            keep_step, solver_result, dfx.RESULTS.successful
        )
        result = dfx.RESULTS.where(dfx.is_okay(s.result), solver_result, s.result)
        result = dfx.RESULTS.where(dfx.is_okay(result), controller_result, result)
        interpolator = solver.interpolation_cls(t0=s.tprev, t1=s.tnext, **dense_info)

        def save_cond(c):
            i, _ = c
            return keep_step & (ts[i] <= s.tnext) & (i < n)

        def save_body(c):
            i, ys = c
            t = ts[i]
            row = fn(t, interpolator.evaluate(t), args)
            return i + 1, jtu.tree_map(lambda r, b: b.at[i].set(r), row, ys)

        save_index, ys = _while(
            save_cond, save_body, (s.save_index, s.ys), lambda c: c[1], batched
        )
        return _State(
            tprev, tnext, y, solver_state, controller_state, result,
            s.num_steps + 1,
            s.num_accepted_steps + jnp.where(keep_step, 1, 0),
            s.num_rejected_steps + jnp.where(keep_step, 0, 1),
            save_index, ys,
        )  # fmt: skip

    final = _while(cond, body, init, lambda s: s.ys, batched)
    result = dfx.RESULTS.where(
        going(final), dfx.RESULTS.max_steps_reached, final.result
    )
    stats = {
        "num_steps": final.num_steps,
        "num_accepted_steps": final.num_accepted_steps,
        "num_rejected_steps": final.num_rejected_steps,
        "max_steps": max_steps,
    }
    return Solution(final.ys, result, stats)
