"""Shuttle controllers: the nonlinear compensator (law B) and law A (spec 4).

Both are actuator effects (`AbstractActuator`): the model asks them for the
shuttle's surge force and yaw moment and saturates the answer smoothly at
`X_max`, `N_max`. Gains are differentiable array fields (shape `(2,)`: channel 0
is the span d, channel 1 the heading error y2 = wrap(psi2 - psi_L)).

Outputs (spec 4.1): y1 = d, the hawser span, reference `d_ref`; y2 = wrap(psi2 -
psi_L), psi_L the bearing of the hawser seen from the shuttle bow, reference 0.

Integral action (law B with `K_I`) needs the integrals of the output errors in the
ODE state: `TandemWithIntegrator` wraps a `Tandem` and appends them (14 states).
"""

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import FloatScalar, f64
from .._model import AbstractModel
from .._validate import check_nonnegative, check_positive, check_shape
from .vessels import (
    AbstractActuator,
    Tandem,
    current_at,
    point_acceleration,
    point_kinematics,
    rot,
    smooth_clip,
    vessel_loads,
    wrap,
)


def _param(default=None):
    conv = f64
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


def _gains(x):
    return jnp.broadcast_to(jnp.asarray(x, dtype=jnp.float64), (2,))


def _optional_param():
    conv = lambda x: None if x is None else _gains(x)
    return eqx.field(converter=conv, default=None)


class NonlinearCompensator(AbstractActuator):
    """Law B: exact input-output linearisation of (d, y2) (spec 4.2).

    y'' = a(X) + G(X) u with a = y''(X, 0), G = jacfwd(u -> y''(X, u)) (exact: y''
    is affine in u). Command u = G^-1 (nu_cmd - a), nu_cmd = -K_P (y - y_ref) -
    K_D y' - K_I z, with z = int (y - y_ref) dt when integral action is on. G is
    inverted in the units of the actuator limits with a tiny Tikhonov term
    (`reg`), a guard for the singularity e . x_b2 = 0.

    Integral action removes the steady output error that a wrong internal model
    leaves (at rest K_P e = a_true - a, G being exact when the error is in the
    loads). The integrals z are states of the ODE:
    simulate with `TandemWithIntegrator(tandem)` (`tandem_controlled(K_I=...)`
    builds it), which hands them to the compensator as `integral` at every
    evaluation. Anti-windup by back-calculation in output-acceleration units: the
    model-predicted output acceleration of the saturated command,
    nu_sat = a + G sat(u), bleeds the integrator,
    z' = (y - y_ref) + K_aw (nu_cmd - nu_sat), so that while an actuator is at
    its limit the integral term settles at the excess instead of growing
    (tracking rate K_aw K_I; both channels, through G, so one actuator at its
    limit holds back the integrators of both outputs it drives).

    **Arguments:**

    - `K_P` (s^-2), `K_D` (s^-1): gains, shape (2,) (span, heading).
    - `K_I`: integral gains, s^-3, shape (2,) or a scalar for both; the spec's
      setting for model-error tests is omega^3/10. Default None: K_I = 0 and no
      integrator state (the law as without integral action). A given `K_I`, 0
      included, needs the integrator states (`TandemWithIntegrator`).
    - `K_aw`: back-calculation gains, s^2, shape (2,) (default 400 s^2 =
      1/omega^2 at the default omega = 0.05 rad/s: tracking time 1/(K_aw K_I),
      200 s at K_I = omega^3/10, the integral time K_P/K_I).
    - `d_ref`: span reference, m.
    - `X_max` (N), `N_max` (N m): actuator limits.
    - `reg`: relative Tikhonov regularisation of G.
    - `internal_model`, `internal_effects`: the model the compensator believes in
      (default: the plant's own model and effects), for model-mismatch studies.
    - `integral`: the integrator states z = (int (d - d_ref) dt (m s),
      int y2 dt (rad s)) at the current evaluation; set by `TandemWithIntegrator`
      from the ODE state (leave None).
    """

    K_P: Float[Array, "2"] = _param((0.0025, 0.0025))
    K_D: Float[Array, "2"] = _param((0.1, 0.1))
    K_I: Float[Array, "2"] | None = _optional_param()
    K_aw: Float[Array, "2"] = _param((400.0, 400.0))
    d_ref: FloatScalar = _param(81.47)
    X_max: FloatScalar = _param(1.5e6)
    N_max: FloatScalar = _param(1.0e8)
    reg: FloatScalar = _param(1e-8)
    internal_model: object = None
    internal_effects: tuple | None = None
    integral: Float[Array, "2"] | None = _optional_param()

    def __check_init__(self):
        check_shape("K_P", self.K_P, (2,), "(span, heading)")
        check_shape("K_D", self.K_D, (2,), "(span, heading)")
        check_nonnegative("K_P", self.K_P, "s^-2")
        check_nonnegative("K_D", self.K_D, "s^-1")
        if self.K_I is not None:
            check_nonnegative("K_I", self.K_I, "s^-3")
        check_nonnegative("K_aw", self.K_aw, "s^2")
        check_positive("d_ref", self.d_ref, "m")
        check_positive("X_max", self.X_max, "N")
        check_positive("N_max", self.N_max, "N m")
        check_nonnegative("reg", self.reg)

    @classmethod
    def from_bandwidth(cls, omega=0.05, zeta=1.0, K_I=None, **kw):
        """Gains K_P = omega^2, K_D = 2 zeta omega (rad/s), both channels, and the
        back-calculation gain K_aw = 1/omega^2 (s^2).

        `K_I` (s^-3, None: no integral action) is passed on as is; with `zeta` = 1
        the closed loop of each channel is then s^3 + 2 omega s^2 + omega^2 s +
        K_I, stable for K_I < 2 omega^3. The spec's K_I = omega^3/10 puts its poles
        at -0.133, -0.587 and -1.280 omega: the slow one (150 s at omega = 0.05
        rad/s) is the integrator's, -K_I/K_P = -omega/10 to first order."""
        check_nonnegative("omega", omega, "rad/s")
        check_nonnegative("zeta", zeta)
        omega = _gains(omega)
        zeta = _gains(zeta)
        kw.setdefault("K_aw", 1.0 / omega**2)
        return cls(K_P=omega**2, K_D=2 * zeta * omega, K_I=K_I, **kw)

    def command(self, t, y, model, effects, env):
        return self.command_and_rate(t, y, model, effects, env)[0]

    def command_and_rate(self, t, y, model, effects, env):
        """The unsaturated command u = (X_ctl, N_ctl) (N, N m) and the rate of the
        integrator states z' (m, rad; zeros without integral action), shape (2,)
        each, at the vessel state `y` (12,)."""
        if self.K_I is not None and self.integral is None:
            raise ValueError(
                "`K_I` needs the integrals of the output errors in the ODE state: "
                "simulate the scene with the model `TandemWithIntegrator(tandem)` "
                "(`tandem_controlled(K_I=...)` builds it)."
            )
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
        if self.K_I is not None:
            nu_cmd = nu_cmd - self.K_I * self.integral
        scale = jnp.stack([self.X_max, self.N_max])
        Gs = G * scale[None, :]
        lam = (self.reg * jnp.max(jnp.abs(Gs))) ** 2
        us = jnp.linalg.solve(Gs.T @ Gs + lam * jnp.eye(2), Gs.T @ (nu_cmd - a))
        u = us * scale
        if self.K_I is None:
            return u, jnp.zeros_like(err)
        u_sat = jnp.stack(
            [smooth_clip(u[0], self.X_max), smooth_clip(u[1], self.N_max)]
        )
        nu_sat = a + G @ u_sat
        return u, err + self.K_aw * (nu_cmd - nu_sat)


class TandemWithIntegrator(AbstractModel):
    """A `Tandem` whose state carries the compensator's integrator states.

    State: `(x1, y1, psi1, u1, v1, r1, x2, y2, psi2, u2, v2, r2, z_d, z_y2)`: the
    tandem's 12 states, then z = (int (d - d_ref) dt (m s), int y2 dt (rad s)).
    The scene must name a `NonlinearCompensator` with `K_I`.

    Why a wrapper: the integrals are controller states, not vessel states. Kept
    apart, the `Tandem` (its equilibria, stability analysis, observables and every
    scene without integral action) keeps its 12-state layout, and the compensator
    keeps the actuator interface `command(t, y, model, effects, env)`: at every
    evaluation this model puts z into the compensator (`integral` field, a
    functional update, so z stays differentiable), asks it once for the command
    and z', saturates the command as the `Tandem` does and hands it to
    `Tandem.vector_field_with_input`.

    **Arguments:**

    - `plant`: the `Tandem` (massless hawser).
    """

    plant: Tandem
    n_vessels: ClassVar[int] = 2
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = Tandem.accepts

    def __check_init__(self):
        if not isinstance(self.plant, Tandem):
            raise ValueError(
                "`plant` must be a `Tandem` (integral action is not available with "
                f"a line hawser); got {type(self.plant).__name__}."
            )

    def state_shape(self):
        return (14,)

    def project(self, y):
        return y

    def split(self, y):
        """(vessel state `(12,)`, integrator states `(2,)`)."""
        return y[:12], y[12:]

    def _bind(self, effects, z):
        """The scene's effects with `z` in the compensator, and the compensator."""
        idx = [i for i, e in enumerate(effects) if isinstance(e, NonlinearCompensator)]
        if len(idx) != 1 or effects[idx[0]].K_I is None:
            raise ValueError(
                "a TandemWithIntegrator scene must name one NonlinearCompensator "
                "with `K_I` (NonlinearCompensator.from_bandwidth(K_I=...))."
            )
        i = idx[0]
        act = eqx.tree_at(
            lambda c: c.integral, effects[i], z, is_leaf=lambda x: x is None
        )
        return effects[:i] + (act,) + effects[i + 1 :], act

    def vector_field(self, t, y, effects, env):
        yv, z = self.split(y)
        effects, act = self._bind(effects, z)
        u, dz = act.command_and_rate(t, yv, self.plant, effects, env)
        u = jnp.stack([smooth_clip(u[0], act.X_max), smooth_clip(u[1], act.N_max)])
        dyv = self.plant.vector_field_with_input(t, yv, effects, env, u)
        return jnp.concatenate([dyv, dz])

    def observables(self, t, y, effects, env):
        """The `Tandem`'s observables and `integral`, the integrator states z."""
        yv, z = self.split(y)
        effects, _ = self._bind(effects, z)
        obs = self.plant.observables(t, yv, effects, env)
        obs["integral"] = z
        return obs


class ComputedForcePD(AbstractActuator):
    """Law A: body-frame computed force plus PD (spec 4.3).

    X_ctl = m11 [K_P0 (d - d_ref) + K_D0 d'] - X_ext - m22 v_r r,
    N_ctl = m66 [-K_P1 y2 - K_D1 y2'] - N_ext, with X_ext, N_ext the model's
    current, wind and hawser loads on the shuttle. Assumes the hawser lies
    roughly along the shuttle axis. Arguments as `NonlinearCompensator`.
    """

    K_P: Float[Array, "2"] = _param((0.0025, 0.0025))
    K_D: Float[Array, "2"] = _param((0.1, 0.1))
    d_ref: FloatScalar = _param(81.47)
    X_max: FloatScalar = _param(1.5e6)
    N_max: FloatScalar = _param(1.0e8)

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
        omega = _gains(omega)
        zeta = _gains(zeta)
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
