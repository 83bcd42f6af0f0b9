"""Vessels in the horizontal plane: the turret FPSO + shuttle tanker tandem.

Model and loads follow ``specs/tanker.md`` (sections 1-3); equation numbers below
refer to its sections.

* ``Hull``: the particulars of one hull (array fields, differentiable).
* ``Tandem``: FPSO (vessel 1) + shuttle (vessel 2), 12 states
  ``X = (x1, y1, psi1, u1, v1, r1, x2, y2, psi2, u2, v2, r2)`` (spec 1.2).
* ``MooredFPSO``: the FPSO alone (6 states), for the turret-position check S0.

Loads are effects (a scene names the ones it calls for; an absent load is not
traced):

* ``ShortWingCurrent``: the Leite et al. (1998) short-wing static current model
  plus the yaw-rate terms (3.1), in the scene's current (``Environment.current``,
  evaluated at each vessel at the surface). The kinetics are written in velocities
  relative to the water; a scene without a current has still water.
* ``OCIMFWind``: OCIMF (1977) tanker wind coefficients, smooth Fourier fit (3.2).
* ``Hawser``: tension-only nonlinear hawser with smooth slack (3.3).
* ``TurretMooring``: isotropic hardening spring + damper at the FPSO turret (3.4).
* ``LinearDamping``: optional extra linear damping (3.5).
* ``ConstantThrust``: the uncontrolled shuttle actuator (astern pull, 3.6); the
  feedback controllers are in ``autopilot.py``. Every actuator is saturated
  smoothly at its limits (`X_max`, `N_max`).

Every load is an ``AbstractVesselLoad`` (the one protocol of
``jaxstring.AbstractLoad``): ``forces(t, kin, env)`` maps the vessels' kinematics
(``VesselKinematics``) and the scene's ``Environment`` (water and air density,
viscosity, current) to body-axis loads (X, Y, N) on each vessel.

Earth frame: x north, y east, angles clockwise from north seen from above.
"""

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import FloatScalar, f64, host_op
from .._effect import AbstractEffect, AbstractLoad
from .._environment import Environment
from .._model import AbstractModel
from .._validate import (
    check_fields,
    check_finite,
    check_nonnegative,
    check_positive,
    check_shape,
    is_concrete,
)


# Smoothing of |x| and sgn(x) (spec 3.1, [R]).
EPS_V = 1e-3  # m/s
EPS_R = 1e-6  # rad/s
EPS_U = 0.01  # m/s, floor of the current speed U


def _param(default=None):
    conv = f64
    if default is None:
        return eqx.field(converter=conv)
    return eqx.field(converter=conv, default=default)


def _sabs(x, eps):
    return jnp.sqrt(x * x + eps * eps)


def rot(psi):
    """Rotation body -> earth, `R(psi)` of spec 1.1."""
    c, s = jnp.cos(psi), jnp.sin(psi)
    return jnp.array([[c, -s], [s, c]])


def wrap(a):
    """Angle wrapped to (-pi, pi]."""
    return host_op(lambda xp, a: xp.arctan2(xp.sin(a), xp.cos(a)), a)


def cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def smooth_clip(u, limit):
    """Saturate `u` to (-limit, limit), C-infinity, exact identity away from the
    limits (the transition is 1 % of the limit wide). Never reaches the limit."""
    w = 0.01 * limit
    s = u - w * jax.nn.softplus((u - limit) / w) + w * jax.nn.softplus((-u - limit) / w)
    # Far in saturation u - (u - limit) rounds to a hair above the limit.
    return jnp.clip(s, -limit, limit)


# ---------------------------------------------------------------------------
# Hull particulars


class Hull(eqx.Module):
    """Particulars of one hull (spec section 5). All fields are SI arrays.

    **Arguments:** `L` (Lpp, m), `B` (beam, m), `T` (draught, m), `C_B` (block
    coefficient), `m` (mass, kg), `S` (wetted surface, m^2), `I_z` (yaw inertia,
    kg m^2), `A11`, `A22` (added masses, kg), `A66` (added yaw inertia, kg m^2),
    `C_Y` (cross-flow drag coefficient), `lam_p` (cross-flow lever l_p/L),
    `A_F`, `A_L` (frontal and lateral wind areas, m^2).
    Use `make_hull` to get the added masses from the spec's formulas.
    """

    L: FloatScalar = _param()
    B: FloatScalar = _param()
    T: FloatScalar = _param()
    C_B: FloatScalar = _param()
    m: FloatScalar = _param()
    S: FloatScalar = _param()
    I_z: FloatScalar = _param()
    A11: FloatScalar = _param()
    A22: FloatScalar = _param()
    A66: FloatScalar = _param()
    C_Y: FloatScalar = _param()
    lam_p: FloatScalar = _param()
    A_F: FloatScalar = _param()
    A_L: FloatScalar = _param()

    def __check_init__(self):
        for name, unit in (
            ("L", "m"), ("B", "m"), ("T", "m"), ("C_B", ""), ("m", "kg"),
            ("S", "m^2"), ("I_z", "kg m^2"), ("C_Y", ""), ("A_F", "m^2"),
            ("A_L", "m^2"),
        ):  # fmt: skip
            check_positive(name, getattr(self, name), unit)
        for name in ("A11", "A22", "A66"):
            check_nonnegative(name, getattr(self, name))
        check_finite("lam_p", self.lam_p)
        if is_concrete(self.C_B) and float(self.C_B) > 1.0:
            raise ValueError(f"`C_B` must be in (0, 1]; got {float(self.C_B)!r}.")

    @property
    def m11(self):
        return self.m + self.A11

    @property
    def m22(self):
        return self.m + self.A22

    @property
    def m66(self):
        return self.I_z + self.A66


def make_hull(
    L, B, T, C_B, S, A_F, A_L, m=None, I_z=None, C_Y=0.55, lam_p=0.05, rho=None
) -> Hull:
    """A `Hull` with the spec's added masses (section 5).

    `m` defaults to rho L B T C_B, `I_z` to (0.25 L)^2 m; A11 is Soding's surge added
    mass 2.7 rho V^(5/3)/L^2 [S2], A22 and A66 Clarke et al. (1983) [S3]. `rho`:
    the water the hull floats in, kg/m^3 (default `Environment().rho_water`, the
    spec's sea water).
    """
    if rho is None:
        rho = float(Environment().rho_water)
    for name, v, unit in (
        ("L", L, "m"),
        ("B", B, "m"),
        ("T", T, "m"),
        ("C_B", C_B, ""),
        ("rho", rho, "kg/m^3"),
    ):
        check_positive(name, v, unit)
    if m is None:
        m = rho * L * B * T * C_B
    check_positive("m", m, "kg")
    if I_z is None:
        I_z = (0.25 * L) ** 2 * m
    vol = m / rho
    A11 = 2.7 * rho * vol ** (5.0 / 3.0) / L**2
    A22 = 0.5 * math.pi * rho * T**2 * L * (1 + 0.16 * C_B * B / T - 5.1 * (B / L) ** 2)
    A66 = (
        0.5 * math.pi * rho * T**2 * L**3
        * (1.0 / 12.0 + 0.017 * C_B * B / T - 0.33 * B / L)
    )  # fmt: skip
    return Hull(
        L=L,
        B=B,
        T=T,
        C_B=C_B,
        m=m,
        S=S,
        I_z=I_z,
        A11=A11,
        A22=A22,
        A66=A66,
        C_Y=C_Y,
        lam_p=lam_p,
        A_F=A_F,
        A_L=A_L,
    )


# Spec section 5: the turret FPSO (converted VLCC, [S1 dimensions.m]) and the
# Suezmax-class DP shuttle tanker ([R]); the shuttle's mass follows from its
# displacement (make_hull with m=None).
_PARTICULARS = ("L", "B", "T", "C_B", "m", "S", "A_F", "A_L", "C_Y", "lam_p")
_SPEC_HULLS = {
    #           L      B     T     C_B   m       S        A_F     A_L      C_Y   lam_p
    "fpso":    (320.0, 54.5, 21.5, 0.85, 3.10e8, 27447.0, 3939.0, 14368.0, 0.52, 0.05),
    "shuttle": (250.0, 46.0, 13.5, 0.82, None,   15170.0, 1000.0, 3000.0,  0.55, 0.05),
}  # fmt: skip


def _spec_hull(which, overrides) -> Hull:
    return make_hull(**{**dict(zip(_PARTICULARS, _SPEC_HULLS[which])), **overrides})


def fpso_hull(**overrides) -> Hull:
    """The turret FPSO of the spec (converted VLCC, [S1 dimensions.m]); keyword
    arguments override its particulars (see `make_hull`)."""
    return _spec_hull("fpso", overrides)


def shuttle_hull(**overrides) -> Hull:
    """The Suezmax-class DP shuttle tanker of the spec ([R]); keyword arguments
    override its particulars (see `make_hull`)."""
    return _spec_hull("shuttle", overrides)


def _stack(*hulls):
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *hulls)


# ---------------------------------------------------------------------------
# Effects


class VesselKinematics(eqx.Module):
    """Kinematics of the vessels, handed to the loads.

    **Fields:**

    - `eta`: positions and headings `(n, 3)` (m, m, rad).
    - `nu`: body velocities `(n, 3)` (m/s, m/s, rad/s).
    - `current`: the water velocity at each vessel, earth axes, `(n, 2)` m/s.
    - `vessels`: the model (its hulls, `hulls()`, and attachment points `x_t`,
      `x_h1`, `x_h2`).
    """

    eta: Float[Array, "n 3"]
    nu: Float[Array, "n 3"]
    current: Float[Array, "n 2"]
    vessels: AbstractModel


class AbstractVesselLoad(AbstractLoad):
    """A load on the vessels: body-axis (X, Y, N) on each vessel."""

    @abc.abstractmethod
    def forces(self, t, kin: VesselKinematics, env) -> Array:
        """Body-axis loads, shape `(n_vessels, 3)` (N, N, N m)."""


class AbstractActuator(AbstractEffect):
    """The shuttle's surge force and yaw moment (spec 3.6). At most one per scene.

    The model saturates the `command` smoothly to |X| < X_max, |N| < N_max."""

    X_max: eqx.AbstractVar[FloatScalar]
    N_max: eqx.AbstractVar[FloatScalar]

    @abc.abstractmethod
    def command(self, t, y, model, effects, env) -> Array:
        """Unsaturated (X_ctl, N_ctl), N and N m, at state `y` of `model` under the
        scene's `effects` in `env`."""


class ShortWingCurrent(AbstractVesselLoad):
    """The current's load on the hulls: short-wing model + yaw-rate terms.

    The current is the scene's `Environment.current` (for the spec's steady
    current of speed U_c flowing toward beta_c: `UniformCurrent((U_c cos beta_c,
    U_c sin beta_c, 0))`, see `current_field`); the water density and viscosity
    are `Environment.rho_water` and `Environment.nu_water`.

    **Arguments:**

    - `yaw_rate_terms`: include the yaw-rate (dynamic) terms (static).
    - `surge_yaw_term`: include the surge `-(pi/4) rho T^2 L v_r r` term, which may
      overlap with the `-A22 v_r r` Coriolis term (spec 2.2; kept by default as
      in the prototype).
    """

    yaw_rate_terms: bool = eqx.field(static=True, default=True)
    surge_yaw_term: bool = eqx.field(static=True, default=True)

    def forces(self, t, kin, env):
        del t
        one = lambda h, eta, nu, vc: self._one(h, eta, nu, vc, env)
        return jax.vmap(one)(kin.vessels.hulls(), kin.eta, kin.nu, kin.current)

    def _one(self, h, eta, nu, vc, env):
        rho = env.rho_water
        u, v, r = nu
        uc, vc_b = rot(eta[2]).T @ vc
        u_r, v_r = u - uc, v - vc_b
        uf, vf = -u_r, -v_r
        U = jnp.sqrt(uf * uf + vf * vf + EPS_U**2)
        L, T, B = h.L, h.T, h.B
        tau = math.pi * T / L
        Re = U * L / env.nu_water
        Cf = 0.09375 / (jnp.log10(Re) - 2.0) ** 2
        avf, auf = _sabs(vf, EPS_V), _sabs(uf, EPS_V)
        q = 0.5 * rho * L * T
        X = q * (Cf * (h.S / (L * T)) * U * uf - 0.5 * tau * uf * vf**2 / U)
        Y = q * (
            (h.C_Y - 0.5 * tau) * vf * avf
            + 0.5 * tau * vf**3 / U
            + tau * (1 + 0.4 * h.C_B * B / T) * vf * auf
        )
        N = (
            q
            * L
            * (
                -h.lam_p * (h.C_Y - 0.5 * tau) * vf * avf
                - tau * uf * vf
                - ((U + auf) / (2 * U)) ** 2 * tau * (0.5 - 2.4 * T / L) * vf * auf
            )
        )
        if self.yaw_rate_terms:
            Cd2 = (math.pi * T / (2 * L)) * (1 - 4.4 * B / L + 0.16 * B / T)
            Cd6 = (math.pi * T / (4 * L)) * (1 + 0.16 * B / T - 2.2 * B / L)
            ar = _sabs(r, EPS_R)
            X = X - (math.pi / 16) * rho * T**2 * L**2 * jnp.tanh(u_r / EPS_V) * r**2
            if self.surge_yaw_term:
                X = X - (math.pi / 4) * rho * T**2 * L * v_r * r
            Y = Y + (
                0.5 * rho * T * L**2 * Cd2 * u_r * r
                - 0.035 * rho * T * L**2 * v_r * r
                - 0.007 * rho * T * L**3 * ar * r
            )
            N = N + (
                -0.5 * rho * T * L**3 * Cd6 * _sabs(u_r, EPS_V) * r
                - 0.15 * rho * T * L**3 * h.C_Y * _sabs(v_r, EPS_V) * r
                - (1.0 / 32.0) * rho * T * L**4 * h.C_Y * ar * r
            )
        return jnp.stack([X, Y, N])


# OCIMF (1977) loaded / ballast tanker coefficients, least-squares Fourier fit
# (spec 3.2): C_X = a0 + sum a_k cos k theta; C_Y, C_N = sum b_k sin k theta.
OCIMF_FIT = {
    "loaded": (
        (-0.0319, -0.7834, -0.0514, -0.0785, 0.0104),
        (0.0, -0.7322, 0.0407, 0.0077, 0.0147),
        (0.0, 0.1360, -0.0537, 0.0187, -0.0071),
    ),
    "ballast": (
        (0.0201, -0.5993, -0.0514, -0.1165, -0.0697),
        (0.0, -0.9694, -0.0422, 0.0173, 0.0104),
        (0.0, 0.0480, -0.1109, 0.0158, 0.0004),
    ),
}


def ocimf_coefficients(theta, loading="loaded"):
    """(C_X, C_Y, C_N) of the smooth OCIMF fit at the coming-from angle `theta`."""
    cx, cy, cn = (jnp.asarray(c) for c in OCIMF_FIT[loading])
    k = jnp.arange(5)
    cos_k, sin_k = jnp.cos(k * theta[..., None]), jnp.sin(k * theta[..., None])
    return (cos_k @ cx, sin_k @ cy, sin_k @ cn)


class OCIMFWind(AbstractVesselLoad):
    """Steady uniform wind with OCIMF tanker coefficients (spec 3.2).

    **Arguments:**

    - `speed`: wind speed at 10 m, m/s (>= 0).
    - `direction`: direction *toward which* it blows, rad from north.
    - `loading`: coefficient set per vessel, `"loaded"` or `"ballast"` (static;
      default loaded for both).
    """

    speed: FloatScalar = _param(0.0)
    direction: FloatScalar = _param(math.pi)
    loading: tuple[str, ...] = eqx.field(static=True, default=("loaded", "loaded"))

    def __check_init__(self):
        check_nonnegative("speed", self.speed, "m/s")
        check_finite("direction", self.direction)
        for s in self.loading:
            if s not in OCIMF_FIT:
                raise ValueError(
                    f"`loading` must hold 'loaded' or 'ballast'; got {s!r}."
                )

    def forces(self, t, kin, env):
        del t
        n = kin.eta.shape[0]
        coef = jnp.asarray([OCIMF_FIT[self.loading[i]] for i in range(n)])
        Vw = self.speed * jnp.stack([jnp.cos(self.direction), jnp.sin(self.direction)])
        one = lambda h, eta, nu, c: self._one(h, eta, nu, c, Vw, env.rho_air)
        return jax.vmap(one)(kin.vessels.hulls(), kin.eta, kin.nu, coef)

    def _one(self, h, eta, nu, coef, Vw, rho_air):
        ua, va = rot(eta[2]).T @ Vw - nu[:2]
        Va2 = ua * ua + va * va + EPS_V**2
        Va = jnp.sqrt(Va2)
        # theta = wrap(atan2(va, ua) - pi): cos theta = -ua/Va, sin theta = -va/Va.
        c1, s1 = -ua / Va, -va / Va
        c2, s2 = c1 * c1 - s1 * s1, 2 * s1 * c1
        c3, s3 = c1 * c2 - s1 * s2, s1 * c2 + c1 * s2
        c4, s4 = c2 * c2 - s2 * s2, 2 * s2 * c2
        cosk = jnp.stack([jnp.ones_like(c1), c1, c2, c3, c4])
        sink = jnp.stack([jnp.zeros_like(s1), s1, s2, s3, s4])
        CX, CY, CN = coef[0] @ cosk, coef[1] @ sink, coef[2] @ sink
        q = 0.5 * rho_air * Va2
        return jnp.stack([q * h.A_F * CX, q * h.A_L * CY, q * h.A_L * h.L * CN])


# The spec's hawser: unstretched length (m) and small-stretch stiffness (N/m).
HAWSER_L0 = 80.0
HAWSER_K_H = 2.0e5


class Hawser(AbstractVesselLoad):
    """Tension-only nonlinear hawser from the FPSO stern to the shuttle bow (3.3).

    T = k_h d+ (1 + (d+/delta_h)^2), d+ = s softplus((d - l0)/s), plus an optional
    damping c_h d' gated by sigmoid((d - l0)/s).

    **Arguments:** `l0` (unstretched length, m), `k_h` (N/m), `delta_h` (hardening
    length, m), `s` (slack smoothing length, m), `c_h` (damping, N s/m, >= 0).
    """

    l0: FloatScalar = _param(HAWSER_L0)
    k_h: FloatScalar = _param(HAWSER_K_H)
    delta_h: FloatScalar = _param(10.0)
    s: FloatScalar = _param(0.05)
    c_h: FloatScalar = _param(0.0)

    def __check_init__(self):
        check_fields(
            self,
            positive={"l0": "m", "k_h": "N/m", "delta_h": "m", "s": "m"},
            nonnegative={"c_h": "N s/m"},
        )

    def tension_of_stretch(self, delta):
        dp = self.s * jax.nn.softplus(delta / self.s)
        return self.k_h * dp * (1 + (dp / self.delta_h) ** 2)

    def stretch_for_tension(self, T):
        """Stretch d - l0 (m) at which the hawser carries tension `T` (N)."""

        # Newton on the cubic for d+, then invert the softplus.
        def newton(_, dp):
            g = self.k_h * dp * (1 + (dp / self.delta_h) ** 2) - T
            dg = self.k_h * (1 + 3 * (dp / self.delta_h) ** 2)
            return dp - g / dg

        dp = jax.lax.fori_loop(0, 30, newton, T / self.k_h)
        z = dp / self.s
        return self.s * (z + jnp.log(-jnp.expm1(-z)))

    def geometry(self, model, eta, nu):
        """(span d, unit e from shuttle bow to FPSO stern, Delta, d_dot)."""
        P1, V1 = point_kinematics(eta[0], nu[0], model.x_h1)
        P2, V2 = point_kinematics(eta[1], nu[1], model.x_h2)
        D = P1 - P2
        d = jnp.sqrt(jnp.sum(D * D))
        e = D / d
        return d, e, D, jnp.dot(e, V1 - V2)

    def tension(self, model, eta, nu):
        d, _, _, d_dot = self.geometry(model, eta, nu)
        delta = d - self.l0
        T = self.tension_of_stretch(delta)
        return T + self.c_h * d_dot * jax.nn.sigmoid(delta / self.s)

    def forces(self, t, kin, env):
        del t, env
        model, eta, nu = kin.vessels, kin.eta, kin.nu
        _require_tandem(model, "Hawser")
        _, e, _, _ = self.geometry(model, eta, nu)
        T = self.tension(model, eta, nu)
        F = T * e  # on the shuttle at P2; -F on the FPSO at P1
        return jnp.stack(
            [
                _point_load(eta[0], -F, model.x_h1),
                _point_load(eta[1], F, model.x_h2),
            ]
        )


class TurretMooring(AbstractVesselLoad):
    """Turret mooring of the FPSO (vessel 1) to the earth origin (spec 3.4).

    F = -k_m (1 + |P_T|^2/rho_m^2) P_T - c_m V_T at the turret; free to rotate.

    **Arguments:** `k_m` (N/m), `rho_m` (hardening length, m), `c_m` (N s/m).
    """

    k_m: FloatScalar = _param(1.0e5)
    rho_m: FloatScalar = _param(50.0)
    c_m: FloatScalar = _param(6.0e5)

    def __check_init__(self):
        check_positive("k_m", self.k_m, "N/m")
        check_positive("rho_m", self.rho_m, "m")
        check_nonnegative("c_m", self.c_m, "N s/m")

    def forces(self, t, kin, env):
        del t, env
        model, eta, nu = kin.vessels, kin.eta, kin.nu
        P, V = point_kinematics(eta[0], nu[0], model.x_t)
        F = -self.k_m * (1 + jnp.sum(P * P) / self.rho_m**2) * P - self.c_m * V
        out = jnp.zeros_like(eta)
        return out.at[0].set(_point_load(eta[0], F, model.x_t))


class LinearDamping(AbstractVesselLoad):
    """Optional linear damping -diag(d_u, d_v, d_r) nu_r on each vessel (3.5).

    **Arguments:** `fpso`, `shuttle`: (d_u N s/m, d_v N s/m, d_r N m s), >= 0."""

    fpso: Float[Array, "3"] = _param((0.0, 0.0, 0.0))
    shuttle: Float[Array, "3"] = _param((0.0, 0.0, 0.0))

    def __check_init__(self):
        for name in ("fpso", "shuttle"):
            check_shape(name, getattr(self, name), (3,), "(d_u, d_v, d_r)")
            check_nonnegative(name, getattr(self, name))

    def forces(self, t, kin, env):
        del t, env
        n = kin.eta.shape[0]
        d = jnp.stack([self.fpso, self.shuttle])[:n]
        nu_r = kin.nu - jax.vmap(
            lambda e, vc: jnp.concatenate([rot(e[2]).T @ vc, jnp.zeros(1)])
        )(kin.eta, kin.current)
        return -d * nu_r


class ConstantThrust(AbstractActuator):
    """Uncontrolled shuttle actuator: X_ctl = -F_ast (astern pull), N_ctl = N.

    **Arguments:** `F_ast` (astern pull, N), `N` (yaw moment, N m), `X_max`,
    `N_max` (limits, > 0)."""

    F_ast: FloatScalar = _param(0.0)
    N: FloatScalar = _param(0.0)
    X_max: FloatScalar = _param(1.5e6)
    N_max: FloatScalar = _param(1.0e8)

    def __check_init__(self):
        check_finite("F_ast", self.F_ast)
        check_finite("N", self.N)
        check_positive("X_max", self.X_max, "N")
        check_positive("N_max", self.N_max, "N m")

    def command(self, t, y, model, effects, env):
        del t, y, model, effects, env
        return jnp.stack([-self.F_ast, self.N])


# ---------------------------------------------------------------------------
# Kinematics helpers (spec 1.3)


def point_kinematics(eta, nu, xP):
    """Earth position and velocity of the centreline point at body x = `xP`."""
    R = rot(eta[2])
    p = eta[:2] + R[:, 0] * xP
    V = R @ jnp.stack([nu[0], nu[1] + xP * nu[2]])
    return p, V


def point_acceleration(eta, nu, nu_dot, xP):
    """Earth acceleration of the centreline point at body x = `xP`."""
    u, v, r = nu
    a = jnp.stack([nu_dot[0], nu_dot[1] + xP * nu_dot[2]]) + r * jnp.stack(
        [-(v + xP * r), u]
    )
    return rot(eta[2]) @ a


def _point_load(eta, F, xP):
    f = rot(eta[2]).T @ F
    return jnp.stack([f[0], f[1], xP * f[1]])


def _require_tandem(model, what):
    if model.n_vessels < 2:
        raise ValueError(f"`{what}` needs two vessels (a Tandem model).")


def hull_clearance(model, eta):
    """Distance between the hull centreline segments minus (B1 + B2)/2, m (< 0:
    the hulls overlap)."""
    h1, h2 = model.fpso, model.shuttle
    a0 = eta[0, :2] - rot(eta[0, 2])[:, 0] * h1.L / 2
    a1 = eta[0, :2] + rot(eta[0, 2])[:, 0] * h1.L / 2
    b0 = eta[1, :2] - rot(eta[1, 2])[:, 0] * h2.L / 2
    b1 = eta[1, :2] + rot(eta[1, 2])[:, 0] * h2.L / 2

    def pt_seg(p, q0, q1):
        d = q1 - q0
        s = jnp.clip(jnp.dot(p - q0, d) / jnp.dot(d, d), 0.0, 1.0)
        w = p - (q0 + s * d)
        return jnp.sqrt(jnp.dot(w, w))

    dmin = jnp.min(
        jnp.stack(
            [
                pt_seg(a0, b0, b1),
                pt_seg(a1, b0, b1),
                pt_seg(b0, a0, a1),
                pt_seg(b1, a0, a1),
            ]
        )  # fmt: skip
    )
    # Proper intersection of the two segments: distance 0.
    o1 = cross2(a1 - a0, b0 - a0)
    o2 = cross2(a1 - a0, b1 - a0)
    o3 = cross2(b1 - b0, a0 - b0)
    o4 = cross2(b1 - b0, a1 - b0)
    crossing = (o1 * o2 < 0) & (o3 * o4 < 0)
    dmin = jnp.where(crossing, 0.0, dmin)
    return dmin - 0.5 * (h1.B + h2.B)


# ---------------------------------------------------------------------------
# Models


def current_at(t, eta, env):
    """Water velocity (earth axes, m/s) at each vessel `(n, 2)`, at the surface;
    zero in still water."""
    surface = jnp.concatenate([eta[:, :2], jnp.zeros_like(eta[:, :1])], axis=1)
    return env.water_velocity(t, surface)[:, :2]


def vessel_kinematics(model, t, y, env) -> VesselKinematics:
    """The `VesselKinematics` of state `y` of `model` in `env`."""
    s = y.reshape(model.n_vessels, 6)
    eta, nu = s[:, :3], s[:, 3:]
    return VesselKinematics(eta, nu, current_at(t, eta, env), model)


def _actuator(effects):
    acts = [e for e in effects if isinstance(e, AbstractActuator)]
    if len(acts) > 1:
        raise ValueError("a scene may name at most one actuator (controller).")
    return acts[0] if acts else None


def vessel_loads(model, t, y, effects, env):
    """Sum of the body-axis loads of the scene's load effects (actuator excluded),
    shape `(n_vessels, 3)` (N, N, N m)."""
    kin = vessel_kinematics(model, t, y, env)
    tau = jnp.zeros((model.n_vessels, 3), y.dtype)
    for e in effects:
        if isinstance(e, AbstractVesselLoad):
            tau = tau + e.forces(t, kin, env)
    return tau


def _rhs(model, t, y, effects, env, u, extra=None):
    """dX/dt with the shuttle input `u` = (X_ctl, N_ctl) (None: no actuator) and
    `extra` body-axis loads `(n_vessels, 3)` (None: none)."""
    n = model.n_vessels
    s = y.reshape(n, 6)
    eta, nu = s[:, :3], s[:, 3:]
    vc = current_at(t, eta, env)
    tau = vessel_loads(model, t, y, effects, env)
    if extra is not None:
        tau = tau + extra
    if u is not None:
        _require_tandem(model, "actuator")
        tau = tau.at[-1, 0].add(u[0]).at[-1, 2].add(u[1])
    h = model.hulls()

    def one(h, eta, nu, tau, vc):
        psi = eta[2]
        u_, v_, r = nu
        uc, vcb = rot(psi).T @ vc
        u_r, v_r = u_ - uc, v_ - vcb
        # spec 2.2: M nu_r' + C(nu_r) nu_r = tau, yaw row of C dropped.
        du_r = (tau[0] + h.m22 * v_r * r) / h.m11
        dv_r = (tau[1] - h.m11 * u_r * r) / h.m22
        dr = tau[2] / h.m66
        c, s_ = jnp.cos(psi), jnp.sin(psi)
        return jnp.stack(
            [u_ * c - v_ * s_, u_ * s_ + v_ * c, r, du_r + r * vcb, dv_r - r * uc, dr]
        )

    return jax.vmap(one)(h, eta, nu, tau, vc).reshape(-1)


def _check_point(name, x, L):
    if is_concrete(x) and is_concrete(L):
        if not math.isfinite(float(x)) or abs(float(x)) > float(L) / 2:
            raise ValueError(
                f"`{name}` must lie on the hull, |{name}| <= L/2 = {float(L) / 2:g} m; "
                f"got {float(x)!r}."
            )


class Tandem(AbstractModel):
    """Turret FPSO + shuttle tanker connected by a hawser (spec sections 1-2).

    State: `X = (x1, y1, psi1, u1, v1, r1, x2, y2, psi2, u2, v2, r2)` (m, rad,
    body velocities m/s and rad/s). Loads come from the scene's effects.

    **Arguments:**

    - `fpso`, `shuttle`: `Hull`s (default: the spec's).
    - `x_t`: turret position on the FPSO centreline, m (|x_t| <= L1/2).
    - `x_h1`: FPSO stern fairlead, m (|x_h1| <= L1/2).
    - `x_h2`: shuttle bow fairlead, m (|x_h2| <= L2/2).
    """

    fpso: Hull
    shuttle: Hull
    x_t: FloatScalar = _param(128.0)
    x_h1: FloatScalar = _param(-160.0)
    x_h2: FloatScalar = _param(125.0)
    n_vessels: ClassVar[int] = 2
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = (AbstractVesselLoad, AbstractActuator)

    def __check_init__(self):
        if not isinstance(self.fpso, Hull) or not isinstance(self.shuttle, Hull):
            raise ValueError(
                "`fpso` and `shuttle` must be `Hull`s; got "
                f"{type(self.fpso).__name__} and {type(self.shuttle).__name__}."
            )
        _check_point("x_t", self.x_t, self.fpso.L)
        _check_point("x_h1", self.x_h1, self.fpso.L)
        _check_point("x_h2", self.x_h2, self.shuttle.L)

    def hulls(self):
        return _stack(self.fpso, self.shuttle)

    def state_shape(self):
        return (12,)

    def project(self, y):
        return y

    def vector_field(self, t, y, effects, env):
        act = _actuator(effects)
        u = None
        if act is not None:
            u = saturated_command(act, t, y, self, effects, env)
        return _rhs(self, t, y, effects, env, u)

    def vector_field_with_input(self, t, y, effects, env, u):
        """dX/dt with the shuttle input `u` = (X_ctl, N_ctl) in place of the scene's
        actuator (used by the controllers)."""
        return _rhs(self, t, y, effects, env, u)

    def observables(self, t, y, effects, env):
        """Headings (wrapped), span and tension of the hawser, hull clearance,
        actuator output, hull positions."""
        s = y.reshape(2, 6)
        eta, nu = s[:, :3], s[:, 3:]
        P1, _ = point_kinematics(eta[0], nu[0], self.x_h1)
        P2, _ = point_kinematics(eta[1], nu[1], self.x_h2)
        D = P1 - P2
        span = jnp.sqrt(jnp.sum(D * D))
        hawsers = [e for e in effects if isinstance(e, Hawser)]
        tension = hawsers[0].tension(self, eta, nu) if hawsers else jnp.zeros(())
        act = _actuator(effects)
        if act is not None:
            ctl = saturated_command(act, t, y, self, effects, env)
        else:
            ctl = jnp.zeros(2)
        psi_L = jnp.arctan2(D[1], D[0])
        return {
            "positions": eta[:, :2],
            "headings": wrap(eta[:, 2]),
            "span": span,
            "tension": tension,
            "clearance": hull_clearance(self, eta),
            "control": ctl,
            "heading_error": wrap(eta[1, 2] - psi_L),
            "fairleads": jnp.stack([P1, P2]),
        }


def saturated_command(act, t, y, model, effects, env):
    """The actuator's command saturated smoothly at its limits."""
    u = act.command(t, y, model, effects, env)
    return jnp.stack([smooth_clip(u[0], act.X_max), smooth_clip(u[1], act.N_max)])


class MooredFPSO(AbstractModel):
    """The FPSO alone on its turret (spec S0): 6 states (x, y, psi, u, v, r).

    **Arguments:** `fpso` (a `Hull`), `x_t` (turret position, m, |x_t| <= L/2).
    """

    fpso: Hull
    x_t: FloatScalar = _param(128.0)
    n_vessels: ClassVar[int] = 1
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = (AbstractVesselLoad,)

    def __check_init__(self):
        if not isinstance(self.fpso, Hull):
            raise ValueError(f"`fpso` must be a `Hull`; got {self.fpso!r}.")
        _check_point("x_t", self.x_t, self.fpso.L)

    def hulls(self):
        return _stack(self.fpso)

    def state_shape(self):
        return (6,)

    def project(self, y):
        return y

    def vector_field(self, t, y, effects, env):
        return _rhs(self, t, y, effects, env, None)

    def observables(self, t, y, effects, env):
        del t, effects, env
        P, _ = point_kinematics(y[:3], y[3:], self.x_t)
        return {
            "positions": y[None, :2],
            "headings": wrap(y[None, 2]),
            "turret_offset": jnp.sqrt(jnp.sum(P * P)),
        }
