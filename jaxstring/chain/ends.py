"""Ends and schedules of a chain: how the end points of a tether or a mooring line
are held (fixed, on a prescribed path, moved by any function of time, coupled to
another model, free), and piecewise-linear schedules of time (paths, released
lengths)."""

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._arrays import f64 as _f64, param as _param
from .._validate import check_finite, is_concrete


class PiecewiseLinear(eqx.Module):
    """A piecewise-linear function of time, constant before the first and after the
    last knot, optionally smoothed by a moving average over `smoothing` seconds.

    The smoothed schedule is the exact box-filter average of the piecewise-linear one:
    equal to it away from the knots, with the velocity ramped linearly over
    `smoothing` seconds around each knot (finite acceleration). With `smoothing = 0`
    (the paper's schedules) the velocity jumps at the knots and the acceleration is 0.

    **Arguments:**

    - `times`: knot times, shape `(K,)`, s, strictly increasing.
    - `values`: values at the knots, shape `(K,)` or `(K, 3)` (m for positions).
    - `smoothing`: width of the moving average, s (>= 0; structure, not traced).
    """

    times: Float[Array, " K"] = _param()
    values: Float[Array, "K ..."] = _param()
    smoothing: float = eqx.field(static=True, default=0.0)

    def __check_init__(self):
        if jnp.ndim(self.times) != 1 or jnp.shape(self.times)[0] < 1:
            raise ValueError(
                f"`times` must be a 1-d array of knot times, s; got shape "
                f"{jnp.shape(self.times)}."
            )
        if (
            jnp.ndim(self.values) < 1
            or jnp.shape(self.values)[0] != jnp.shape(self.times)[0]
        ):
            raise ValueError(
                "`values` must have one row per knot time "
                f"({jnp.shape(self.times)[0]}); "
                f"got shape {jnp.shape(self.values)}."
            )
        check_finite("times", self.times)
        check_finite("values", self.values)
        if is_concrete(self.times) and np.any(np.diff(np.asarray(self.times)) <= 0):
            raise ValueError(
                "`times` must be strictly increasing (s); got "
                f"{np.asarray(self.times)}."
            )
        if not (isinstance(self.smoothing, (int, float)) and self.smoothing >= 0):
            raise ValueError(
                f"`smoothing` must be a number >= 0 s; got {self.smoothing!r}."
            )

    def _segment(self, t):
        """Index i of the segment holding t, the knot value there and the slope."""
        K = self.times.shape[0]
        if K == 1:
            zero = jnp.zeros_like(self.values[0])
            return 0, self.values[0], zero
        i = jnp.clip(jnp.searchsorted(self.times, t, side="right") - 1, 0, K - 2)
        dt = self.times[i + 1] - self.times[i]
        slope = (self.values[i + 1] - self.values[i]) / dt
        return i, self.values[i], slope

    def _raw(self, t, segment):
        """Piecewise-linear value and slope (slope 0 outside the knots) at t, in
        its `segment`."""
        i, v0, slope = segment
        tc = jnp.clip(t, self.times[0], self.times[-1])
        value = v0 + slope * (tc - self.times[i])
        inside = (t >= self.times[0]) & (t < self.times[-1])
        return value, jnp.where(inside, slope, jnp.zeros_like(slope))

    def _antiderivative(self, t, segment):
        """X(t) = int_{times[0]}^t x, with x constant outside the knots."""
        v = self.values
        if self.times.shape[0] == 1:
            return v[0] * (t - self.times[0])
        seg = 0.5 * (v[1:] + v[:-1]) * _expand(jnp.diff(self.times), v)
        C = jnp.concatenate([jnp.zeros_like(v[:1]), jnp.cumsum(seg, axis=0)], axis=0)
        i, v0, slope = segment
        tc = jnp.clip(t, self.times[0], self.times[-1])
        s = tc - self.times[i]
        inner = C[i] + v0 * s + 0.5 * slope * s**2
        before = v[0] * jnp.minimum(t - self.times[0], 0.0)
        after = v[-1] * jnp.maximum(t - self.times[-1], 0.0)
        return inner + before + after

    def kinematics(self, t):
        """Value, rate and acceleration at `t`, from one segment lookup (two with
        smoothing: at t -/+ smoothing / 2)."""
        if self.smoothing == 0:
            value, slope = self._raw(t, self._segment(t))
            return value, slope, jnp.zeros_like(value)
        h = 0.5 * self.smoothing
        lo, hi = self._segment(t - h), self._segment(t + h)
        (x_lo, v_lo), (x_hi, v_hi) = self._raw(t - h, lo), self._raw(t + h, hi)
        X_lo, X_hi = self._antiderivative(t - h, lo), self._antiderivative(t + h, hi)
        return (X_hi - X_lo) / (2 * h), (x_hi - x_lo) / (2 * h), (v_hi - v_lo) / (2 * h)

    def value(self, t):
        return self.kinematics(t)[0]

    def rate(self, t):
        return self.kinematics(t)[1]

    def accel(self, t):
        return self.kinematics(t)[2]


def _expand(x, like):
    return x.reshape(x.shape + (1,) * (like.ndim - 1))


class EndKinematics(eqx.Module):
    """Position (m), velocity (m/s), acceleration (m/s^2) of a mount point, `(3,)`."""

    position: Float[Array, "3"]
    velocity: Float[Array, "3"]
    acceleration: Float[Array, "3"]


class AbstractEnd(eqx.Module):
    """How one end of the tether is held."""

    attached: ClassVar[bool] = True

    @abc.abstractmethod
    def kinematics(self, t) -> EndKinematics:
        """Kinematics of the mount point at time `t` (s)."""


def _check_point(name, x):
    if jnp.shape(x) != (3,):
        raise ValueError(f"`{name}` must have shape (3,) (m); got {jnp.shape(x)}.")
    check_finite(name, x)


class FixedEnd(AbstractEnd):
    """A mount fixed in space. `position`: shape `(3,)`, m."""

    position: Float[Array, "3"] = _param()

    def __check_init__(self):
        _check_point("position", self.position)

    def kinematics(self, t):
        del t
        z = jnp.zeros(3)
        return EndKinematics(self.position, z, z)


class PrescribedEnd(AbstractEnd):
    """A mount moving on a prescribed path (paper section 5: piecewise linear).

    **Arguments:**

    - `times`: knot times, `(K,)`, s, strictly increasing.
    - `positions`: mount positions at the knots, `(K, 3)`, m.
    - `smoothing`: velocity ramp width at the knots, s (0: the paper's sharp corners).
    """

    path: PiecewiseLinear

    def __init__(self, times, positions, smoothing: float = 0.0):
        positions = _f64(positions)
        if jnp.ndim(positions) != 2 or jnp.shape(positions)[1] != 3:
            raise ValueError(
                f"`positions` must have shape (K, 3), m; got {jnp.shape(positions)}."
            )
        self.path = PiecewiseLinear(times, positions, smoothing)

    def kinematics(self, t):
        return EndKinematics(*self.path.kinematics(t))


class CoupledEnd(AbstractEnd):
    """A mount whose kinematics another model supplies (a vessel): use
    `tether.rates(t, y, effects, root=..., fast=...)`, which returns the end forces."""

    def kinematics(self, t):
        raise ValueError(
            "a CoupledEnd has no kinematics of its own: call `rates(t, y, effects, "
            "root=EndKinematics(...), fast=EndKinematics(...))` from the coupled model."
        )


class FreeEnd(AbstractEnd):
    """A free running end (no mount, no end link). Only for `fast`."""

    attached: ClassVar[bool] = False

    def kinematics(self, t):
        raise ValueError("a FreeEnd has no mount kinematics.")


class MotionEnd(AbstractEnd):
    """A point moved by any JAX function of time: `fn(t, params) -> (3,)`, m.

    Velocity and acceleration are its first two time derivatives (forward-mode
    autodiff). `fn` is structure; its parameters `params` (a PyTree of arrays) stay
    differentiable and vmappable.
    """

    fn: object = eqx.field(static=True)
    params: object = None

    def __check_init__(self):
        if not callable(self.fn):
            raise ValueError(f"`fn` must be callable; got {self.fn!r}.")

    def kinematics(self, t):
        t = _f64(t)

        def pos(s):
            return jnp.asarray(self.fn(s, self.params), jnp.float64)

        def vel(s):
            return jax.jvp(pos, (s,), (jnp.ones_like(s),))

        (p, v), (_, a) = jax.jvp(vel, (t,), (jnp.ones_like(t),))
        return EndKinematics(p, v, a)
