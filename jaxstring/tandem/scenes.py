"""Named scenes of the FPSO + shuttle tanker tandem (spec section 6, S0-S4).

Default environment: current U_c = 1 m/s flowing south (coming from the north);
wind blowing toward `pi + Delta_w`, so `Delta_w` is the angle between where the
wind and where the current come from.
"""

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp

from .._arrays import f64, host_op
from .._environment import Environment, UniformCurrent
from .._programs import eager_jit
from .._scene import Scene
from .._validate import check_choice, check_finite, check_nonnegative, check_positive
from .autopilot import ComputedForcePD, NonlinearCompensator, TandemWithIntegrator
from .line import HAWSER_KINDS, LINE_OPTIONS, with_line
from .turret import TurretLines, turret_lines, with_dynamic_mooring
from .vessels import (
    HAWSER_K_H,
    HAWSER_L0,
    AbstractVesselLoad,
    ConstantThrust,
    Hawser,
    MooredFPSO,
    OCIMFWind,
    ShortWingCurrent,
    Tandem,
    TurretMooring,
    fpso_hull,
    shuttle_hull,
    vessel_loads,
)


# S4 environments: name -> (V_w m/s, Delta_w deg)
ENVIRONMENTS = {
    "current": (0.0, 0.0),
    "wind5_0": (5.0, 0.0),
    "wind15_90": (15.0, 90.0),
    "wind15_180": (15.0, 180.0),
}


def current_field(U_c=1.0, beta_c=math.pi) -> UniformCurrent:
    """The spec's steady uniform current: speed `U_c` (m/s) flowing toward
    `beta_c` (rad from north, clockwise; pi = flowing south), earth axes."""
    return UniformCurrent(
        host_op(
            lambda xp, u, b: xp.stack([u * xp.cos(b), u * xp.sin(b), xp.zeros(())]),
            U_c,
            beta_c,
        )
    )


def environment(U_c=1.0, V_w=0.0, Delta_w_deg=0.0, beta_c=math.pi):
    """The spec's environment: `(effects, env)`, the current's and (when `V_w` > 0)
    the wind's load effects and the `Environment` holding the current."""
    check_nonnegative("U_c", U_c, "m/s")
    check_nonnegative("V_w", V_w, "m/s")
    check_finite("Delta_w_deg", Delta_w_deg)
    effects = (ShortWingCurrent(),)
    if not (isinstance(V_w, (int, float)) and V_w == 0.0):
        # Spec section 6: the wind blows toward beta_w = pi + Delta_w (beta_c = pi).
        beta_w = beta_c + math.radians(Delta_w_deg)
        effects += (OCIMFWind(speed=V_w, direction=beta_w),)
    return effects, Environment(current=current_field(U_c, beta_c))


def tandem_model(x_t=None, x_h1=None, x_h2=None, fpso=None, shuttle=None) -> Tandem:
    """The spec's tandem (defaults: x_t = 0.40 L1, x_h1 = -L1/2, x_h2 = +L2/2)."""
    fpso = fpso_hull() if fpso is None else fpso
    shuttle = shuttle_hull() if shuttle is None else shuttle
    kw = {}
    for k, v in (("x_t", x_t), ("x_h1", x_h1), ("x_h2", x_h2)):
        if v is not None:
            kw[k] = v
    return Tandem(fpso=fpso, shuttle=shuttle, **kw)


def _axial_loads(model, effects, env, psi):
    """Surge loads on each vessel at rest, heading `psi`, from current and wind."""
    n = model.n_vessels
    y = jnp.tile(jnp.array([0.0, 0.0, psi, 0.0, 0.0, 0.0]), n)
    loads = tuple(
        e
        for e in effects
        if isinstance(e, AbstractVesselLoad)
        and not isinstance(e, (Hawser, TurretMooring, TurretLines))
    )
    return vessel_loads(model, 0.0, y, loads, env)[:, 0]


def _mooring_offset(mooring, F, heading=0.0):
    """Turret offset r (m) where the mooring's restoring force balances F (N):
    k_m (1 + r^2/rho_m^2) r = F for the spring; for `TurretLines`, the lines'
    force along the heading's unit vector with the turret at -r times it."""
    if isinstance(mooring, TurretLines):
        return mooring.offset_for_force(F, heading)
    k, rho2 = mooring.k_m, mooring.rho_m**2

    def newton(_, r):
        g = k * (1 + r**2 / rho2) * r - F
        return r - g / (k * (1 + 3 * r**2 / rho2))

    return jax.lax.fori_loop(0, 40, newton, F / k)


def aligned_equilibrium(model, effects, env, F_ast=0.0, heading=0.0):
    """The aligned equilibrium (both vessels heading `heading`, shuttle astern) for
    loads along that axis (current, and wind along the current): exact, from the
    surge balances. Returns the state."""
    return _aligned_equilibrium(model, effects, env, f64(F_ast), f64(heading))


@eager_jit(tiered=True)
def _aligned_equilibrium(model, effects, env, F_ast, heading):
    hawsers = [e for e in effects if isinstance(e, Hawser)]
    moorings = [e for e in effects if isinstance(e, (TurretMooring, TurretLines))]
    X = _axial_loads(model, effects, env, heading)
    e = jnp.stack([jnp.cos(heading), jnp.sin(heading)])
    if model.n_vessels == 1:
        r = _mooring_offset(moorings[0], -X[0], heading)
        p1 = -(model.x_t + r) * e
        return jnp.concatenate([p1, jnp.array([heading, 0.0, 0.0, 0.0])])
    # Floor the tension: with a head wind stronger than the current drag there is
    # no aligned equilibrium, and this state is only a start (1 kN).
    T = jnp.maximum(-X[1] + F_ast, 1.0e3)
    d = hawsers[0].l0 + hawsers[0].stretch_for_tension(T)
    r = _mooring_offset(moorings[0], -X[0] + T, heading)
    p1 = -(model.x_t + r) * e
    P1 = p1 + model.x_h1 * e
    p2 = P1 - (d + model.x_h2) * e
    z = jnp.zeros(3)
    h = jnp.array([heading])
    return jnp.concatenate([p1, h, z, p2, h, z])


MOORINGS = ("spring", "lines", "dynamic")


def turret_mooring(mooring=None, k_m=1.0e5, c_m=6.0e5):
    """The FPSO's turret mooring effect named by `mooring`: None or "spring" (the
    spec's hardening spring, `TurretMooring(k_m, c_m)`), "lines" (the packaged
    deck's catenary lines, `turret_lines()`, damping `c_m`), a path of a MoorDyn
    deck (its lines on the turret), or a `TurretMooring` / `TurretLines` (as
    it is). "dynamic": the quasi-static lines, from which a scene builder starts
    before it integrates the lines with the vessels (`_dynamic`)."""
    if isinstance(mooring, (TurretMooring, TurretLines)):
        return mooring
    if mooring is None or mooring == "spring":
        return TurretMooring(k_m=k_m, c_m=c_m)
    if mooring in ("lines", "dynamic"):
        return turret_lines(c_m=c_m)
    if isinstance(mooring, (str, os.PathLike)) and os.path.isfile(mooring):
        return turret_lines(mooring, c_m=c_m)
    raise ValueError(
        f"`mooring` must be one of {MOORINGS}, the path of a MoorDyn deck, a "
        f"TurretMooring or a TurretLines; got {mooring!r}."
    )


def _dynamic(scene, mooring):
    """`scene` with the packaged deck's lines integrated with the vessels
    (`with_dynamic_mooring`) when `mooring` is "dynamic", else as it is."""
    if isinstance(mooring, str) and mooring == "dynamic":
        return with_dynamic_mooring(scene)
    return scene


def _check_dynamic(mooring, **refused):
    """Refuse `mooring="dynamic"` with the options in `refused` that are set
    (name -> (value, True where it is refused))."""
    if not (isinstance(mooring, str) and mooring == "dynamic"):
        return
    for name, (value, bad) in refused.items():
        if bad:
            raise ValueError(
                f"`mooring='dynamic'` integrates the lines with a Tandem or a "
                f"MooredFPSO; it does not combine with `{name}`={value!r}."
            )


def _perturb_shuttle_heading(model, y, angle):
    """Turn the shuttle by `angle` (rad) about its bow fairlead."""
    return _turn_shuttle(model, y, f64(angle))


@eager_jit(tiered=True)
def _turn_shuttle(model, y, angle):
    psi = y[8]
    P2 = y[6:8] + model.x_h2 * jnp.stack([jnp.cos(psi), jnp.sin(psi)])
    psi_new = psi + angle
    p2 = P2 - model.x_h2 * jnp.stack([jnp.cos(psi_new), jnp.sin(psi_new)])
    return y.at[6:8].set(p2).at[8].set(psi_new)


def tandem_fpso_alone(
    x_t_over_L=0.40,
    U_c=1.0,
    psi0_deg=10.0,
    t1=20000.0,
    k_m=1.0e5,
    c_m=6.0e5,
    mooring=None,
) -> Scene:
    """S0: the FPSO alone on its turret in current (hawser removed).

    Starts from the heading-into-current equilibrium turned by `psi0_deg` about
    the turret; forward of the critical turret position (0.355 L1) it returns.
    `mooring`: the turret's mooring (`turret_mooring`; default the spec's spring
    of `k_m`, `c_m`; "lines": the packaged deck's catenary lines, quasi-static;
    "dynamic": those lines integrated with the FPSO, `with_dynamic_mooring`).
    """
    check_positive("U_c", U_c, "m/s")
    check_finite("psi0_deg", psi0_deg)
    check_finite("x_t_over_L", x_t_over_L)
    if abs(float(x_t_over_L)) > 0.5:
        raise ValueError(
            "`x_t_over_L` must lie on the hull, in [-0.5, 0.5]; got "
            f"{float(x_t_over_L)!r}."
        )
    fpso = fpso_hull()
    model = MooredFPSO(fpso=fpso, x_t=x_t_over_L * fpso.L)
    effects = (ShortWingCurrent(), turret_mooring(mooring, k_m=k_m, c_m=c_m))
    env = Environment(current=current_field(U_c))
    y = aligned_equilibrium(model, effects, env)
    a = math.radians(psi0_deg)
    PT = y[:2] + model.x_t * jnp.array([1.0, 0.0])
    y = y.at[:2].set(PT - model.x_t * jnp.array([math.cos(a), math.sin(a)]))
    y = y.at[2].set(a)
    sc = Scene(
        model=model, effects=effects, y0=y, t1=t1, name="tandem-fpso-alone", env=env
    )
    return _dynamic(sc, mooring)


def _tandem_effects(U_c, V_w, Delta_w_deg, l0, k_h, F_ast, hawser=None, mooring=None):
    eff, env = environment(U_c=U_c, V_w=V_w, Delta_w_deg=Delta_w_deg)
    hawser = Hawser(l0=l0, k_h=k_h) if hawser is None else hawser
    eff = eff + (hawser, turret_mooring(mooring))
    if F_ast is not None:
        eff = eff + (ConstantThrust(F_ast=F_ast),)
    return eff, env


def tandem_equilibria(
    V_w=0.0,
    Delta_w_deg=0.0,
    U_c=1.0,
    l0=HAWSER_L0,
    k_h=HAWSER_K_H,
    x_t=None,
    t1=1.0e4,
    mooring=None,
) -> Scene:
    """S1/S2: the tandem in current and wind, no thrust; `y0` is the aligned
    state (exact equilibrium for the current alone or wind along it, with the
    spring or a mooring pattern symmetric about the heading). Use
    `find_equilibria(scene)` for all equilibria. `mooring`: the turret's
    (`turret_mooring`: default the spec's spring; "lines": catenary lines,
    quasi-static: the equilibria and their stability are the vessels')."""
    if isinstance(mooring, str) and mooring == "dynamic":
        raise ValueError(
            "`mooring` for the equilibria scene must be 'spring', 'lines', a deck "
            "or an effect (the equilibria and their stability are the vessels' on "
            "quasi-static lines); got 'dynamic'."
        )
    model = tandem_model(x_t=x_t)
    eff, env = _tandem_effects(U_c, V_w, Delta_w_deg, l0, k_h, None, mooring=mooring)
    y0 = aligned_equilibrium(model, eff, env)
    return Scene(
        model=model, effects=eff, y0=y0, t1=t1, name="tandem-equilibria", env=env
    )


def _check_hawser(hawser, line_options):
    """Check `hawser` and `line_options` before a scene is built."""
    check_choice("hawser", hawser, HAWSER_KINDS)
    if line_options is not None and not isinstance(line_options, dict):
        raise ValueError(
            f"`line_options` must be a dict of `with_line` options; got "
            f"{line_options!r}."
        )
    if line_options:
        valid = LINE_OPTIONS
        unknown = sorted(set(line_options) - set(valid))
        if unknown:
            raise ValueError(
                f"unknown `line_options` {', '.join(map(repr, unknown))}; valid: "
                f"{', '.join(map(repr, valid))}."
            )
        if hawser == "massless":
            raise ValueError(
                "`line_options` apply only with hawser='line'; got "
                f"{sorted(line_options)}."
            )


def _hawser_kind(scene, hawser, line_options):
    if hawser == "massless":
        return scene
    return with_line(scene, name=scene.name, **(line_options or {}))


def tandem_fishtail(
    F_ast=0.0,
    perturbation_deg=2.5,
    t1=60000.0,
    U_c=1.0,
    l0: float = HAWSER_L0,
    k_h: float = HAWSER_K_H,
    hawser="massless",
    line_options=None,
    mooring=None,
) -> Scene:
    """S3a: current only, constant astern pull `F_ast` (N), from the aligned
    equilibrium with the shuttle turned by `perturbation_deg` about its bow.
    `mooring`: the turret's (`turret_mooring`: default the spec's spring;
    "lines": the packaged deck's catenary lines, quasi-static; "dynamic": those
    lines integrated with the vessels, `with_dynamic_mooring`).

    `hawser="line"` replaces the massless hawser by a line with mass and drag
    (`with_line`; `line_options`: its keyword arguments, e.g. `N`,
    `mass_per_length`); the vessels start from the same state (the perturbation
    turns the shuttle about its fairlead, so the line's static shape is that of
    the massless equilibrium's span)."""
    check_finite("perturbation_deg", perturbation_deg)
    check_positive("U_c", U_c, "m/s")
    _check_hawser(hawser, line_options)
    _check_dynamic(mooring, hawser=(hawser, hawser != "massless"))
    model = tandem_model()
    eff, env = _tandem_effects(U_c, 0.0, 0.0, l0, k_h, F_ast, mooring=mooring)
    y0 = aligned_equilibrium(model, eff, env, F_ast=F_ast)
    y0 = _perturb_shuttle_heading(model, y0, math.radians(perturbation_deg))
    sc = Scene(model=model, effects=eff, y0=y0, t1=t1, name="tandem-fishtail", env=env)
    return _dynamic(_hawser_kind(sc, hawser, line_options), mooring)


def tandem_hopf(
    F_ast=40.0e3, perturbation_deg=2.5, t1=40000.0, U_c=1.0, mooring=None
) -> Scene:
    """S3b: the fishtail scene at astern pull `F_ast` (N); the Hopf point is near
    43 kN (spec). Sweep `F_ast` with `hopf_sweep`. `mooring`: as in
    `tandem_fishtail`."""
    sc = tandem_fishtail(
        F_ast=F_ast, perturbation_deg=perturbation_deg, t1=t1, U_c=U_c, mooring=mooring
    )
    return Scene(
        model=sc.model,
        effects=sc.effects,
        y0=sc.y0,
        t1=t1,
        name="tandem-hopf",
        env=sc.env,
    )


def controlled_start(model, span=81.0, shuttle_offset_deg=10.0):
    """S4 start: FPSO heading north with its turret at the origin, shuttle bow
    `span` m south of the FPSO stern, shuttle turned `shuttle_offset_deg`."""
    a = math.radians(shuttle_offset_deg)
    p1 = jnp.stack([-model.x_t, jnp.zeros(())])
    P1 = p1 + jnp.stack([model.x_h1, jnp.zeros(())])
    P2 = P1 - jnp.stack([jnp.asarray(span), jnp.zeros(())])
    p2 = P2 - model.x_h2 * jnp.array([math.cos(a), math.sin(a)])
    z = jnp.zeros(3)
    return jnp.concatenate([p1, jnp.zeros(1), z, p2, jnp.array([a]), z])


def tandem_controlled(
    env="current",
    law="B",
    t1=4000.0,
    T_ref=300.0e3,
    omega=0.05,
    zeta=1.0,
    span0=81.0,
    shuttle_offset_deg=10.0,
    X_max=1.5e6,
    N_max=1.0e8,
    U_c=1.0,
    hawser="massless",
    line_options=None,
    K_I=None,
    mooring=None,
) -> Scene:
    """S4: the shuttle under the nonlinear compensator (law "B") or the computed
    force PD (law "A"), in one of `ENVIRONMENTS`.

    The span reference is d_ref = l0 + delta(T_ref) (81.47 m at 300 kN); the
    heading reference is the hawser bearing. Gains: K_P = omega^2, K_D = 2 zeta
    omega on both channels. `hawser="line"`: as in `tandem_fishtail` (the
    controller keeps the massless hawser as its model of the line).

    `K_I` (s^-3, scalar or one per channel; law B with the massless hawser only):
    integral action; the model is then a `TandemWithIntegrator` (14 states, the
    integrators starting at 0). The spec's setting for model-error tests is
    omega^3/10. None: no integral action.

    `mooring`: the FPSO's turret mooring (`turret_mooring`: default the spec's
    spring; "lines": the packaged deck's catenary lines, quasi-static; "dynamic":
    those lines integrated with the vessels, `with_dynamic_mooring`, with the
    massless hawser and no integral action; the controller's model then has no
    mooring force, which it rejects as a disturbance)."""
    check_choice("env", env, tuple(ENVIRONMENTS))
    check_choice("law", law, ("A", "B"))
    if K_I is not None and (law != "B" or hawser != "massless"):
        raise ValueError(
            "`K_I` (integral action) needs law='B' and hawser='massless'; got "
            f"law={law!r}, hawser={hawser!r}."
        )
    check_positive("T_ref", T_ref, "N")
    check_positive("omega", omega, "rad/s")
    check_positive("zeta", zeta)
    check_positive("span0", span0, "m")
    check_finite("shuttle_offset_deg", shuttle_offset_deg)
    V_w, Dw = ENVIRONMENTS[env]
    _check_hawser(hawser, line_options)
    _check_dynamic(
        mooring, hawser=(hawser, hawser != "massless"), K_I=(K_I, K_I is not None)
    )
    model = tandem_model()
    spec_hawser = Hawser()
    d_ref = spec_hawser.l0 + spec_hawser.stretch_for_tension(T_ref)
    kw = dict(omega=omega, zeta=zeta, d_ref=d_ref, X_max=X_max, N_max=N_max)
    if law == "B":
        ctl = NonlinearCompensator.from_bandwidth(K_I=K_I, **kw)
    else:
        ctl = ComputedForcePD.from_bandwidth(**kw)
    eff, env_ = environment(U_c=U_c, V_w=V_w, Delta_w_deg=Dw)
    eff = eff + (spec_hawser, turret_mooring(mooring), ctl)
    y0 = controlled_start(model, span=span0, shuttle_offset_deg=shuttle_offset_deg)
    if K_I is not None:
        model = TandemWithIntegrator(model)
        y0 = jnp.concatenate([y0, jnp.zeros(2)])
    sc = Scene(
        model=model, effects=eff, y0=y0, t1=t1, name="tandem-controlled", env=env_
    )
    return _dynamic(_hawser_kind(sc, hawser, line_options), mooring)


def with_model_mismatch(scene, C_Y_factor=1.2, wind_area_factor=0.8) -> Scene:
    """The S4 `scene` with the compensator believing a wrong model (spec S4,
    recommended test): its internal model has the cross-flow drag coefficient
    C_Y x `C_Y_factor` and the wind areas A_F, A_L x `wind_area_factor` on both
    hulls, while the plant keeps the nominal ones. Needs a `NonlinearCompensator`
    (law B) in the scene."""
    check_positive("C_Y_factor", C_Y_factor)
    check_positive("wind_area_factor", wind_area_factor)
    idx = [
        i for i, e in enumerate(scene.effects) if isinstance(e, NonlinearCompensator)
    ]
    if len(idx) != 1:
        raise ValueError(
            "`with_model_mismatch` needs a scene with one NonlinearCompensator (law B)."
        )
    plant = (
        scene.model.plant
        if isinstance(scene.model, TandemWithIntegrator)
        else scene.model
    )
    if not isinstance(plant, Tandem):
        raise ValueError("`with_model_mismatch` needs a Tandem scene.")

    def believed(h):
        return eqx.tree_at(
            lambda h: (h.C_Y, h.A_F, h.A_L),
            h,
            (h.C_Y * C_Y_factor, h.A_F * wind_area_factor, h.A_L * wind_area_factor),
        )

    internal = eqx.tree_at(
        lambda m: (m.fpso, m.shuttle),
        plant,
        (believed(plant.fpso), believed(plant.shuttle)),
    )
    i = idx[0]
    ctl = eqx.tree_at(
        lambda c: c.internal_model,
        scene.effects[i],
        internal,
        is_leaf=lambda x: x is None,
    )
    return eqx.tree_at(lambda sc: sc.effects[i], scene, ctl)
