"""The result of a simulation."""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int


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
    - `result`: the diffrax result code; `ok`, `status` describe it.
    - `stats`: solver statistics (`num_steps`, `num_accepted_steps`,
      `num_rejected_steps`, `max_steps`).
    - `t_end`, `n_valid`: the last save time reached and the number of valid rows.

    A failed solve keeps the data up to the failure; later rows are NaN.
    """

    ts: Float[Array, " T"]
    ys: Array
    obs: dict
    result: dfx.RESULTS
    stats: dict
    t_end: Float[Array, ""]
    n_valid: Int[Array, ""]

    def __getattr__(self, name):
        # Observables by attribute: traj.positions, traj.tension, ...
        obs = self.__dict__.get("obs")
        if obs is not None and name in obs:
            return obs[name]
        raise AttributeError(name)

    @property
    def ok(self) -> bool:
        return bool(self.result == dfx.RESULTS.successful)

    @property
    def status(self) -> str:
        """'success' or the failure message of the solver."""
        return "success" if self.ok else _message(self.result)

    @property
    def end_mass(self) -> Float[Array, "T dim"]:
        """Position of the end mass (the last node), m."""
        return self.obs["positions"][:, -1, :]

    def summary(self) -> str:
        s = self.stats
        return (
            f"status: {self.status}\n"
            f"steps: {int(s['num_accepted_steps'])} accepted, "
            f"{int(s['num_rejected_steps'])} rejected"
        )


def _message(result) -> str:
    index = int(jnp.asarray(result._value))
    return dfx.RESULTS._index_to_message[index] or "success"
