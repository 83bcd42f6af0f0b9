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
    - `positions`: node positions, pivot included, shape `(T, k + 1, dim)`, m.
    - `velocities`: node velocities, shape `(T, k + 1, dim)`, m/s.
    - `tension`: axial force at the model's tension points (`k` elements in
      displacement variables, `k + 1` nodes in natural variables), shape `(T, .)`, N.
    - `strain`: axial strain at the same points, shape `(T, .)`.
    - `energy`: total mechanical energy, shape `(T,)`, J.
    - `constraint_error`: max | |t| - 1 | of the tangent constraint, shape `(T,)`.
    - `result`: the diffrax result code; `status` and `message` describe it.
    - `stats`: solver statistics (`num_steps`, `num_accepted_steps`,
      `num_rejected_steps`, `max_steps`).

    A failed solve keeps the data up to the failure; `ok` is False, and `t_end` is the
    last time the solver reached.
    """

    ts: Float[Array, " T"]
    ys: Array
    positions: Float[Array, "T n dim"]
    velocities: Float[Array, "T n dim"]
    tension: Float[Array, "T m"]
    strain: Float[Array, "T m"]
    energy: Float[Array, " T"]
    constraint_error: Float[Array, " T"]
    result: dfx.RESULTS
    stats: dict
    t_end: Float[Array, ""]
    n_valid: Int[Array, ""]

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
        return self.positions[:, -1, :]

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
