"""Shuttle controllers: the nonlinear compensator (law B) and law A (spec 4).

Both are actuator effects (`AbstractActuator`): the model asks them for the
shuttle's surge force and yaw moment and saturates the answer smoothly at
`X_max`, `N_max`. Gains are differentiable array fields (shape `(2,)`: channel 0
is the span d, channel 1 the heading error y2 = wrap(psi2 - psi_L)).

Outputs (spec 4.1): y1 = d, the hawser span, reference `d_ref`; y2 = wrap(psi2 -
psi_L), psi_L the bearing of the hawser seen from the shuttle bow, reference 0.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._validate import check_nonnegative, check_positive, check_shape
from .vessels import (
    AbstractActuator,
    current_at,
    point_acceleration,
    point_kinematics,
    rot,
    vessel_loads,
    wrap,
)


def _param(default=None):
    conv = lambda x: jnp.asarray(x, dtype=jnp.float64)
    if default is None:
        return eqx.field(converter=conv)
    return eqx.field(converter=conv, default=default)


def outputs(model, y, nu_dot=None):
    """(y, y_dot, y_ddot) of the two outputs at state `y`, shape (2,) each.

    `nu_dot`: body accelerations `(2, 3)` (from the model); without it y_ddot is
    zero. Spec 4.2: Delta = P1 - P2, e = Delta/d,
    y1'' = e.Delta'' + (|Delta'|^2 - (e.Delta')^2)/d,
    psi_L'' = (Delta x Delta'')/d^2 - 2 (Delta x Delta')(Delta.Delta')/d^4.
    """
    s = y.reshape(2, 6)
    eta, nu = s[:, :3], s[:, 3:]
    P1, V1 = point_kinematics(eta[0], nu[0], model.x_h1)
    P2, V2 = point_kinematics(eta[1], nu[1], model.x_h2)
    D, Dd = P1 - P2, V1 - V2
    d2 = jnp.sum(D * D)
    d = jnp.sqrt(d2)
    e = D / d
    cr = D[0] * Dd[1] - D[1] * Dd[0]
    psi_L = jnp.arctan2(D[1], D[0])
    psi_L_dot = cr / d2
    y_out = jnp.stack([d, wrap(eta[1, 2] - psi_L)])
    y_dot = jnp.stack([jnp.dot(e, Dd), nu[1, 2] - psi_L_dot])
    if nu_dot is None:
        return y_out, y_dot, jnp.zeros(2)
    A1 = point_acceleration(eta[0], nu[0], nu_dot[0], model.x_h1)
    A2 = point_acceleration(eta[1], nu[1], nu_dot[1], model.x_h2)
    Ddd = A1 - A2
    edd = jnp.dot(e, Dd)
    y1dd = jnp.dot(e, Ddd) + (jnp.sum(Dd * Dd) - edd**2) / d
    psi_L_dd = (D[0] * Ddd[1] - D[1] * Ddd[0]) / d2 - 2 * cr * jnp.dot(D, Dd) / d2**2
    y2dd = nu_dot[1, 2] - psi_L_dd
    return y_out, y_dot, jnp.stack([y1dd, y2dd])


def _nu_dot(model, t, y, effects, env, u):
    return model.vector_field_with_input(t, y, effects, env, u).reshape(2, 6)[:, 3:]


class NonlinearCompensator(AbstractActuator):
    """Law B: exact input-output linearisation of (d, y2) (spec 4.2).

    y'' = a(X) + G(X) u with a = y''(X, 0), G = jacfwd(u -> y''(X, u)) (exact: y''
    is affine in u). Command u = G^-1 (nu_cmd - a), nu_cmd = -K_P (y - y_ref) -
    K_D y'. G is inverted in the units of the actuator limits with a tiny Tikhonov
    term (`reg`), a guard for the singularity e . x_b2 = 0.

    **Arguments:**

    - `K_P` (s^-2), `K_D` (s^-1): gains, shape (2,) (span, heading).
    - `d_ref`: span reference, m.
    - `X_max` (N), `N_max` (N m): actuator limits.
    - `reg`: relative Tikhonov regularisation of G.
    - `internal_model`, `internal_effects`: the model the compensator believes in
      (default: the plant's own model and effects), for model-mismatch studies.
    """

    K_P: Float[Array, "2"] = _param((0.0025, 0.0025))
    K_D: Float[Array, "2"] = _param((0.1, 0.1))
    d_ref: Float[Array, ""] = _param(81.47)
    X_max: Float[Array, ""] = _param(1.5e6)
    N_max: Float[Array, ""] = _param(1.0e8)
    reg: Float[Array, ""] = _param(1e-8)
    internal_model: object = None
    internal_effects: tuple | None = None

    def __check_init__(self):
        check_shape("K_P", self.K_P, (2,), "(span, heading)")
        check_shape("K_D", self.K_D, (2,), "(span, heading)")
        check_nonnegative("K_P", self.K_P, "s^-2")
        check_nonnegative("K_D", self.K_D, "s^-1")
        check_positive("d_ref", self.d_ref, "m")
        check_positive("X_max", self.X_max, "N")
        check_positive("N_max", self.N_max, "N m")
        check_nonnegative("reg", self.reg)

    @classmethod
    def from_bandwidth(cls, omega=0.05, zeta=1.0, **kw):
        """Gains K_P = omega^2, K_D = 2 zeta omega (rad/s), both channels."""
        check_nonnegative("omega", omega, "rad/s")
        check_nonnegative("zeta", zeta)
        omega = jnp.broadcast_to(jnp.asarray(omega, dtype=jnp.float64), (2,))
        zeta = jnp.broadcast_to(jnp.asarray(zeta, dtype=jnp.float64), (2,))
        return cls(K_P=omega**2, K_D=2 * zeta * omega, **kw)

    def command(self, t, y, model, effects, env):
        m = model if self.internal_model is None else self.internal_model
        eff = effects if self.internal_effects is None else self.internal_effects

        def ydd(u):
            return outputs(m, y, _nu_dot(m, t, y, eff, env, u))[2]

        zero = jnp.zeros(2, y.dtype)
        a = ydd(zero)
        G = jax.jacfwd(ydd)(zero)
        y_out, y_dot, _ = outputs(m, y)
        err = y_out - jnp.stack([self.d_ref, jnp.zeros(())])
        nu_cmd = -self.K_P * err - self.K_D * y_dot
        scale = jnp.stack([self.X_max, self.N_max])
        Gs = G * scale[None, :]
        lam = (self.reg * jnp.max(jnp.abs(Gs))) ** 2
        us = jnp.linalg.solve(Gs.T @ Gs + lam * jnp.eye(2), Gs.T @ (nu_cmd - a))
        return us * scale


class ComputedForcePD(AbstractActuator):
    """Law A: body-frame computed force plus PD (spec 4.3).

    X_ctl = m11 [K_P0 (d - d_ref) + K_D0 d'] - X_ext - m22 v_r r,
    N_ctl = m66 [-K_P1 y2 - K_D1 y2'] - N_ext, with X_ext, N_ext the model's
    current, wind and hawser loads on the shuttle. Assumes the hawser lies
    roughly along the shuttle axis. Arguments as `NonlinearCompensator`.
    """

    K_P: Float[Array, "2"] = _param((0.0025, 0.0025))
    K_D: Float[Array, "2"] = _param((0.1, 0.1))
    d_ref: Float[Array, ""] = _param(81.47)
    X_max: Float[Array, ""] = _param(1.5e6)
    N_max: Float[Array, ""] = _param(1.0e8)

    def __check_init__(self):
        check_shape("K_P", self.K_P, (2,), "(span, heading)")
        check_shape("K_D", self.K_D, (2,), "(span, heading)")
        check_nonnegative("K_P", self.K_P, "s^-2")
        check_nonnegative("K_D", self.K_D, "s^-1")
        check_positive("d_ref", self.d_ref, "m")
        check_positive("X_max", self.X_max, "N")
        check_positive("N_max", self.N_max, "N m")

    @classmethod
    def from_bandwidth(cls, omega=0.05, zeta=1.0, **kw):
        """Gains K_P = omega^2, K_D = 2 zeta omega (rad/s), both channels."""
        check_nonnegative("omega", omega, "rad/s")
        check_nonnegative("zeta", zeta)
        omega = jnp.broadcast_to(jnp.asarray(omega, dtype=jnp.float64), (2,))
        zeta = jnp.broadcast_to(jnp.asarray(zeta, dtype=jnp.float64), (2,))
        return cls(K_P=omega**2, K_D=2 * zeta * omega, **kw)

    def command(self, t, y, model, effects, env):
        tau = vessel_loads(model, t, y, effects, env)[1]
        h = model.shuttle
        s = y.reshape(2, 6)
        vc = rot(s[1, 2]).T @ current_at(t, s[:, :3], env)[1]
        v_r, r = s[1, 4] - vc[1], s[1, 5]
        y_out, y_dot, _ = outputs(model, y)
        X = h.m11 * (self.K_P[0] * (y_out[0] - self.d_ref) + self.K_D[0] * y_dot[0])
        X = X - tau[0] - h.m22 * v_r * r
        N = h.m66 * (-self.K_P[1] * y_out[1] - self.K_D[1] * y_dot[1]) - tau[2]
        return jnp.stack([X, N])
