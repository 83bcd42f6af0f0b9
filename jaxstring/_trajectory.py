"""The result of a simulation."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._arrays import FloatScalar, IntScalar, host_op


class Trajectory(eqx.Module):
    """Saved states of a simulation with derived observables and solver status.

    **Fields:**

    - `ts`: save times, shape `(T,)`, s.
    - `ys`: states in the model's layout, shape `(T, ...)`.
    - `obs`: dict of observables with a leading time axis (the model's
      `observables`); for strings also available as attributes:
      `positions` and `velocities` (nodes incl. the pivot, `(T, k + 1, dim)`, m and
      m/s), `tension` and `strain` at the tension points (`k` elements in
      displacement variables, `k + 1` nodes in natural variables; N and -),
      `energy` (`(T,)`, J) and `constraint_error` (`(T,)`, max | |t| - 1 |).
    - `result`: the solver's integer result code (0: success; else the index of
      diffrax's `RESULTS`); `ok`, `status` describe it.
    - `stats`: solver statistics (`num_steps`, `num_accepted_steps`,
      `num_rejected_steps`, `max_steps`).
    - `t_end`, `n_valid`: the last save time reached and the number of valid rows.

    A failed solve keeps the data up to the failure; later rows are NaN.
    """

    ts: Float[Array, " T"]
    ys: Array
    obs: dict
    result: IntScalar
    stats: dict
    t_end: FloatScalar
    n_valid: IntScalar

    def __getattr__(self, name):
        # Observables by attribute: traj.positions, traj.tension, ...
        obs = self.__dict__.get("obs")
        if obs is not None and name in obs:
            return obs[name]
        raise AttributeError(name)

    @property
    def ok(self) -> bool:
        return int(np.asarray(self.result)) == 0

    @property
    def status(self) -> str:
        """'success' or the failure message of the solver."""
        if self.ok:
            return "success"
        from ._solvers.diffrax_compat import code_message

        return code_message(int(np.asarray(self.result)))

    @property
    def end_mass(self) -> Float[Array, "T dim"]:
        """Position of the end mass (the last node), m."""
        return host_op(lambda xp, p: p[:, -1, :], self.obs["positions"])

    @classmethod
    def from_solution(cls, ts, ys, result, stats, scene) -> "Trajectory":
        """The Trajectory of saved states `ys` at `ts` of `scene`, with the one
        failure mask; `result`: diffrax's result.

        States after a failure are inf in diffrax's output: observables are evaluated
        on finite states only (the initial state stands in for the others), and
        every row after the first non-finite one is NaN; `n_valid` counts the rows
        before it and `t_end` is the last save time reached."""
        finite = jnp.all(jnp.isfinite(ys.reshape(ys.shape[0], -1)), axis=1)
        n_valid = jnp.sum(jnp.cumprod(finite))
        rows = lambda x: finite.reshape((-1,) + (1,) * (x.ndim - 1))
        safe_ys = jnp.where(rows(ys), ys, scene.y0)
        obs = jax.vmap(lambda t, y: scene.observables(y, t))(ts, safe_ys)
        obs = jax.tree_util.tree_map(lambda x: jnp.where(rows(x), x, jnp.nan), obs)
        stats = {
            key: stats[key]
            for key in ("num_steps", "num_accepted_steps", "num_rejected_steps")
            + (("max_steps",) if "max_steps" in stats else ())
        }
        t_end = jnp.where(n_valid > 0, ts[jnp.maximum(n_valid - 1, 0)], scene.t0)
        from ._solvers.diffrax_compat import result_code

        return cls(ts, ys, obs, result_code(result), stats, t_end, n_valid)

    def summary(self) -> str:
        s = self.stats
        return (
            f"status: {self.status}\n"
            f"steps: {int(s['num_accepted_steps'])} accepted, "
            f"{int(s['num_rejected_steps'])} rejected"
        )
