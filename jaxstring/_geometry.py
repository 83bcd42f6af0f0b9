"""NaN-safe geometry helpers (no physics)."""

import jax.numpy as jnp


def safe_norm(x, axis=-1, keepdims=False):
    """Euclidean norm whose gradient is finite (zero) at x = 0 (double-where trick)."""
    sq = jnp.sum(x * x, axis=axis, keepdims=True)
    is_zero = sq == 0
    safe_sq = jnp.where(is_zero, 1.0, sq)
    n = jnp.where(is_zero, 0.0, jnp.sqrt(safe_sq))
    return n if keepdims else jnp.squeeze(n, axis=axis)


def down(dim: int):
    """Unit vector of gravity: -y in 2D and in 3D (the pendulum swings in x-y)."""
    e = jnp.zeros(dim)
    return e.at[1].set(-1.0)


def direction(theta, dim: int):
    """Unit vector at angle ``theta`` from the downward vertical, towards +x."""
    e = jnp.zeros(dim)
    return e.at[0].set(jnp.sin(theta)).at[1].set(-jnp.cos(theta))
