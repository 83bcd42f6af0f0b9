"""Forward sensitivities integrated with the state, under the solver's error control.

Differentiating a solve in forward mode (diffrax's ``ForwardMode``) gives the
derivative of the discrete solution along the steps the solver chose for the state.
Where the sensitivities vary much faster than the state, those steps do not resolve
them: after the string's slack-and-snap phases the forward-mode derivative of the
end mass can be far off, even of the wrong sign (docs/pendulum.md, "Slack and
snap"; experiments/results/slack_snap_gradients.md).

Here the sensitivities S_j = dy/dtheta_j (along chosen parameter directions) solve
their own ODE beside the state,

    dy/dt = f(t, y, theta),
    dS_j/dt = (df/dy) S_j + df/dtheta_j,    S_j(t0) = dy0/dtheta_j,

as one augmented system that the solver integrates with its error estimate taken
over the state and the sensitivities together (CVODES's ``errconS``). The right-hand
side of the sensitivities is one linearisation of the vector field per evaluation,
applied to every direction. The augmented state keeps the node-major layout
(``(nodes, components x (1 + P))``), so the solvers' band detection finds a chain's
band (width 1 for the string at k = 40).
"""

from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import jax.tree_util as jtu

from ._integrate import integrate, solver_parts
from ._scene import Scene, scene_vector_field
from ._trajectory import Trajectory


def _as_nodes(y):
    """`y` as a 2-d node-major array (a 1-d state: one component per node)."""
    return y.reshape(y.shape[0], -1) if y.ndim >= 2 else y[:, None]


class _AugmentedField(eqx.Module):
    """The vector field of (y, S_1, ..., S_P) stacked along the last axis, S_j the
    derivative of y along the parameter direction `directions[j]`."""

    scene_of: Callable
    directions: jax.Array
    shape: tuple = eqx.field(static=True)
    n_params: int = eqx.field(static=True)

    def split(self, z):
        b = z.shape[-1] // (1 + self.n_params)
        y = z[:, :b].reshape(self.shape)
        S = jnp.stack(
            [
                z[:, b * (j + 1) : b * (j + 2)].reshape(self.shape)
                for j in range(self.n_params)
            ]
        )
        return y, S

    def __call__(self, t, z, x):
        y, S = self.split(z)
        f, lin = jax.linearize(
            lambda yy, xx: scene_vector_field(t, yy, self.scene_of(xx)), y, x
        )
        dS = jax.vmap(lin)(S, self.directions)
        return jnp.concatenate([_as_nodes(f)] + [_as_nodes(d) for d in dS], axis=-1)


def sensitivity_solve(
    scene_of: Callable,
    x,
    directions,
    solver,
    controller,
    ts,
    max_steps,
    dt0,
    batched=False,
):
    """Integrate the scene `scene_of(x)` and its sensitivities to the flat parameter
    vector `x` along the rows of `directions` `(P, x.size)`, saving at `ts`.

    Choose directions that give the sensitivities the scale of the state (e.g. each
    parameter times its own magnitude): the error control weighs them like the
    state. `solver` and `controller` as `simulate` builds them for the scene.
    Returns `(ys, S, sol)`: the states `(T, *y0.shape)`, the sensitivities
    `(P, T, *y0.shape)` and the solution's result and statistics. `batched`:
    traced under `vmap` (`integrate`).
    """
    scene: Scene = scene_of(x)
    y0 = scene.y0
    _, dy0 = jax.linearize(lambda xx: scene_of(xx).y0, x)
    S0 = jax.vmap(dy0)(directions)
    field = _AugmentedField(scene_of, directions, tuple(y0.shape), int(len(directions)))
    z0 = jnp.concatenate([_as_nodes(y0)] + [_as_nodes(s) for s in S0], axis=-1)
    sol = integrate(
        field,
        z0,
        x,
        scene.t0,
        scene.t1,
        solver=solver,
        controller=controller,
        dt0=dt0,
        saveat=dfx.SaveAt(ts=ts),
        max_steps=max_steps,
        # the sensitivities are the derivatives: nothing differentiates this solve
        # (jaxstring's own step loop, `jaxstring._solvers.loop`)
        adjoint=dfx.ForwardMode(),
        batched=batched,
    )
    ys, S = jax.vmap(field.split)(sol.ys)
    return ys, jnp.moveaxis(S, 1, 0), sol


def derivatives(
    scene_of: Callable, x, is_log, config, ts, out_fn: Callable, batched=False
):
    """`out_fn(traj, scene)` at the scene `scene_of(x)` and its derivatives with
    respect to each entry of the flat parameter vector `x`, stacked on a leading
    axis, from one solve of the state and its sensitivities.

    `config` is the solve's `SolveConfig`, `ts` the save times of `traj` (None:
    the configuration's). Each
    direction is its parameter's own magnitude (1 where `is_log`: log-parameters,
    and for a zero value), so that the sensitivities have the state's scale and its
    error control fits them. `batched`: traced under `vmap` (`integrate`)."""
    scene = scene_of(x)
    if ts is None:
        ts = config.save_times(scene.t0, scene.t1)
    solver, controller, dt0 = solver_parts(scene, config)
    scale = lax.stop_gradient(jnp.where(is_log | (x == 0), 1.0, jnp.abs(x)))
    directions = jnp.diag(scale)
    ys, S, sol = sensitivity_solve(
        scene_of, x, directions, solver, controller, ts, config.max_steps, dt0,
        batched,
    )  # fmt: skip

    def out_of(ys_, xx):
        sc = scene_of(xx)
        return out_fn(Trajectory.from_solution(ts, ys_, sol.result, sol.stats, sc), sc)

    value, d = jax.vmap(
        lambda s, e: jax.jvp(out_of, (ys, x), (s, e)), out_axes=(None, 0)
    )(S, directions)
    unscale = lambda a: a / scale.reshape((-1,) + (1,) * (a.ndim - 1))
    return value, jtu.tree_map(unscale, d)
