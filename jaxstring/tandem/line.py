"""The tandem with a real hawser: a tether chain (mass, weight, buoyancy, drag)
between the FPSO stern fairlead and the shuttle bow fairlead.

`TandemLine` couples a `Tandem` (12 vessel states) to any tether model of
`_tether` (`LmsTether` by default: every link a spring of axial stiffness EA,
so a line of EA = k_h l0 reproduces the massless hawser's small-stretch stiffness)
whose two ends are `CoupledEnd`s. State: the flat vector
`(x1, y1, psi1, u1, v1, r1, x2, y2, psi2, u2, v2, r2, p_1, v_1, ..., p_N, v_N)`
(vessel states, then the line's `(N, 6)` node-major block), so the Jacobian is
dense for the vessels and block-banded for the line.

Coupling: the fairleads are the line's end mounts, at depth 0 on the hull
centrelines (`point_kinematics`); the forces the line exerts on the mounts are the
vessels' hawser loads (horizontal components; the vertical part goes into the
hulls' heave, which the 3-DOF model does not have). End accelerations matter only
for tension methods with rigid end links (ACEAM, exact): they come from a first
pass at zero end acceleration, which is accurate to the line/vessel mass ratio
(~1e-5) -- the spring-linked LMS line needs no second pass.

The scene's effects are split by kind: vessel loads and the actuator act on the
vessels, chain loads (`Gravity`, `Buoyancy`, `Drag`) on the line; a massless
`Hawser` in the same scene is refused (the line *is* the hawser). A controller
computes its command from the vessel states with the massless hawser
`controller_hawser` as its internal model of the line (the S4 laws need one), so
the line's mass and drag are a model mismatch the controller has to reject.
"""

from typing import ClassVar

import jax.numpy as jnp
import numpy as np

from .._jit import cpu_jit
from .._lazy import optimistix as optx
from .._model import AbstractModel
from .._programs import eager_jit
from .._validate import check_finite, check_int, check_positive
from ..chain import (
    AbstractChainLoad,
    Buoyancy,
    CoupledEnd,
    Drag,
    EndKinematics,
    Gravity,
)
from ..tether import AbstractTether, LmsTether
from .vessels import (
    HAWSER_K_H,
    HAWSER_L0,
    AbstractActuator,
    AbstractVesselLoad,
    Hawser,
    Tandem,
    _point_load,
    _rhs,
    hull_clearance,
    point_acceleration,
    point_kinematics,
    smooth_clip,
    wrap,
)


LINE_LOADS = (Gravity, Buoyancy, AbstractChainLoad)


def split_line_effects(effects):
    """(vessel effects, line effects); raises on a massless `Hawser` or an effect
    that belongs to neither."""
    vessel, line = [], []
    for e in effects:
        if isinstance(e, Hawser):
            raise ValueError(
                "a TandemLine scene must not name a massless `Hawser`: the line is "
                "the hawser (use `controller_hawser` for a controller's model of it)."
            )
        if isinstance(e, (AbstractVesselLoad, AbstractActuator)):
            vessel.append(e)
        elif isinstance(e, LINE_LOADS):
            line.append(e)
        else:
            raise ValueError(
                f"a TandemLine takes vessel loads, one actuator and chain loads "
                f"(Gravity, Buoyancy, Drag); got {type(e).__name__} in `effects`."
            )
    return tuple(vessel), tuple(line)


def _mount(eta, nu, nu_dot, xP):
    p, v = point_kinematics(eta, nu, xP)
    z = jnp.zeros((1,), p.dtype)
    a = (
        jnp.zeros(2, p.dtype)
        if nu_dot is None
        else point_acceleration(eta, nu, nu_dot, xP)
    )
    return EndKinematics(
        jnp.concatenate([p, z]), jnp.concatenate([v, z]), jnp.concatenate([a, z])
    )


class TandemLine(AbstractModel):
    """FPSO + shuttle joined by a line with mass and drag (a tether chain).

    **Arguments:**

    - `tandem`: the `Tandem` (hulls, turret and fairlead positions).
    - `line`: a tether model (`LmsTether`, `ExactTether` or `AceamTether`) whose
      `root` (FPSO stern) and `fast` (shuttle bow) ends are `CoupledEnd`s; its
      `L` is the line's unstretched length.
    - `controller_hawser`: the massless `Hawser` a controller uses as its model of
      the line (default: `Hawser(l0=line.L, k_h=line.k/line.L)` for an LMS line,
      else `Hawser(l0=line.L)`).
    """

    tandem: Tandem
    line: AbstractTether
    controller_hawser: Hawser
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = (
        AbstractVesselLoad,
        AbstractActuator,
        *LINE_LOADS,
    )

    def __init__(self, tandem, line, controller_hawser=None):
        if not isinstance(tandem, Tandem):
            raise ValueError(f"`tandem` must be a `Tandem`; got {tandem!r}.")
        if not isinstance(line, AbstractTether):
            raise ValueError(
                "`line` must be a jaxstring tether model (LmsTether, ExactTether, "
                f"AceamTether); got {line!r}."
            )
        if not (
            isinstance(line.root, CoupledEnd) and isinstance(line.fast, CoupledEnd)
        ):
            raise ValueError(
                "`line` must have `root=CoupledEnd()` and `fast=CoupledEnd()`: its "
                "ends are the fairleads."
            )
        if line.released is not None:
            raise ValueError("`line` must have a fixed length (`released=None`).")
        if controller_hawser is None:
            if isinstance(line, LmsTether):
                controller_hawser = Hawser(l0=line.L, k_h=line.k / line.L)
            else:
                controller_hawser = Hawser(l0=line.L)
        if not isinstance(controller_hawser, Hawser):
            raise ValueError(
                f"`controller_hawser` must be a `Hawser` or None; got "
                f"{controller_hawser!r}."
            )
        self.tandem = tandem
        self.line = line
        self.controller_hawser = controller_hawser

    @property
    def n_vessels(self):
        return 2

    def state_shape(self):
        return (12 + 6 * self.line.N,)

    def project(self, y):
        return y

    def split(self, y):
        """(vessel state `(12,)`, line state `(N, 6)`)."""
        return y[:12], y[12:].reshape(self.line.N, 6)

    def join(self, yv, yl):
        return jnp.concatenate([yv, jnp.reshape(yl, (-1,))])

    # -- coupling
    def _mounts(self, yv, nu_dot=None):
        s = yv.reshape(2, 6)
        eta, nu = s[:, :3], s[:, 3:]
        nd = (None, None) if nu_dot is None else (nu_dot[0], nu_dot[1])
        root = _mount(eta[0], nu[0], nd[0], self.tandem.x_h1)
        fast = _mount(eta[1], nu[1], nd[1], self.tandem.x_h2)
        return root, fast

    def _line_tau(self, yv, f_root, f_fast):
        s = yv.reshape(2, 6)
        eta = s[:, :3]
        return jnp.stack(
            [
                _point_load(eta[0], f_root[:2], self.tandem.x_h1),
                _point_load(eta[1], f_fast[:2], self.tandem.x_h2),
            ]
        )

    def controller_effects(self, vessel_effects):
        """The effects a controller sees: the vessel effects and its hawser model."""
        return tuple(vessel_effects) + (self.controller_hawser,)

    def _command(self, t, yv, vessel_effects, env):
        acts = [e for e in vessel_effects if isinstance(e, AbstractActuator)]
        if len(acts) > 1:
            raise ValueError("a scene may name at most one actuator (controller).")
        if not acts:
            return None
        act = acts[0]
        u = act.command(
            t, yv, self.tandem, self.controller_effects(vessel_effects), env
        )
        return jnp.stack([smooth_clip(u[0], act.X_max), smooth_clip(u[1], act.N_max)])

    def _rates(self, t, y, effects, env):
        vessel, line_eff = split_line_effects(effects)
        yv, yl = self.split(y)
        u = self._command(t, yv, vessel, env)
        loads = tuple(e for e in vessel if isinstance(e, AbstractVesselLoad))
        root, fast = self._mounts(yv)
        line_rates = lambda root, fast: self.line.rates(
            t, yl, line_eff, env, root=root, fast=fast
        )
        dyl, f_root, f_fast = line_rates(root, fast)
        tau = self._line_tau(yv, f_root, f_fast)
        dyv = _rhs(self.tandem, t, yv, loads, env, u, tau)
        if not isinstance(self.line, LmsTether):
            # Rigid end links: the end forces depend on the mount accelerations.
            nu_dot = dyv.reshape(2, 6)[:, 3:]
            root, fast = self._mounts(yv, nu_dot)
            dyl, f_root, f_fast = line_rates(root, fast)
            tau = self._line_tau(yv, f_root, f_fast)
            dyv = _rhs(self.tandem, t, yv, loads, env, u, tau)
        return dyv, dyl, f_fast, u, root, fast

    def vector_field(self, t, y, effects, env):
        dyv, dyl, *_ = self._rates(t, y, effects, env)
        return self.join(dyv, dyl)

    def observables(self, t, y, effects, env):
        """As `Tandem.observables` (span = fairlead distance, `tension` = the
        horizontal line force on the shuttle's fairlead), plus the line's `nodes`
        (N + 2, 3), `line_tension` (N + 1,) and `sag` (deepest node below the
        fairleads, m)."""
        yv, yl = self.split(y)
        s = yv.reshape(2, 6)
        eta = s[:, :3]
        # the mounts the vector field used (with their accelerations, for rigid
        # end links), so that the link tensions are the ones it applied
        _, _, f_fast, u, root, fast = self._rates(t, y, effects, env)
        _, line_eff = split_line_effects(effects)
        P1, P2 = root.position[:2], fast.position[:2]
        D = P1 - P2
        span = jnp.sqrt(jnp.sum(D * D))
        nodes = jnp.concatenate([root.position[None], yl[:, :3], fast.position[None]])
        ch_T = self.line._tensions(self.line._chain(t, yl, line_eff, env, root, fast))
        psi_L = jnp.arctan2(D[1], D[0])
        return {
            "positions": eta[:, :2],
            "headings": wrap(eta[:, 2]),
            "span": span,
            "tension": jnp.sqrt(jnp.sum(f_fast[:2] ** 2)),
            "clearance": hull_clearance(self.tandem, eta),
            "control": jnp.zeros(2) if u is None else u,
            "heading_error": wrap(eta[1, 2] - psi_L),
            "fairleads": jnp.stack([P1, P2]),
            "nodes": nodes,
            "line_tension": ch_T,
            "sag": -jnp.min(yl[:, 2]),
        }


def hawser_line(
    l0: float = HAWSER_L0,
    k_h: float = HAWSER_K_H,
    N=8,
    d=0.16,
    mass_per_length=25.0,
    added_mass=1.0,
    damping=0.0,
) -> LmsTether:
    """An LMS line standing for the spec's hawser: length `l0` (m), axial stiffness
    EA = `k_h` l0 (the massless hawser's small-stretch stiffness), `N` nodes,
    diameter `d` (m), `mass_per_length` (kg/m; default a 0.16 m nylon hawser, which
    nearly floats), link damping `damping` (N s)."""
    check_positive("l0", l0, "m")
    check_positive("k_h", k_h, "N/m")
    check_int("N", N, 2)
    return LmsTether(
        L=l0,
        d=d,
        mass_per_length=mass_per_length,
        added_mass=added_mass,
        k=k_h * l0,
        c=damping,
        N=N,
        root=CoupledEnd(),
        fast=CoupledEnd(),
    )


def line_effects(c_n=1.0, c_t=0.1):
    """Weight, buoyancy and drag on the line (in the scene's current, the one the
    vessels feel)."""
    # Drag's axial coefficient acts on the wetted surface pi d l_e; c_t / pi puts
    # it on the projected area d l_e, as the tether scenes do
    # (see jaxstring.tether.scenes).
    return (Gravity(), Buoyancy(), Drag(Cd=c_n, CdAx=c_t / jnp.pi))


def _static_residual(p, args):
    line, root, fast, line_eff, env = args
    yl = jnp.concatenate([p, jnp.zeros_like(p)], axis=1)
    dy, _, _ = line.rates(0.0, yl, line_eff, env, root=root, fast=fast)
    return dy[:, 3:] * line.inertia(env)


def _equilibrium_residual(y, scene):
    return scene.vector_field(0.0, y)


@cpu_jit(tiered=True)
def _root(fn, y0, args, max_steps, tol):
    # module-level residuals and one jitted solve: repeated calls with the same
    # structure (N, effects) reuse the compiled solve
    sol = optx.root_find(
        fn, optx.Newton(rtol=tol, atol=tol), y0, args, max_steps=max_steps, throw=False
    )
    return sol.value, jnp.max(jnp.abs(fn(sol.value, args)))


def static_line(model: TandemLine, yv, effects, env, sag_guess=None, max_steps=100):
    """The line's static shape between the fairleads of vessel state `yv` (vessels
    held still; drag of the current of `env` on the still line included): Newton
    (optimistix) on the node forces, from a parabolic guess of depth `sag_guess`
    (m). Returns the line state `(N, 6)` (velocities zero); raises if no shape is
    found."""
    check_finite("yv", yv)
    _, line_eff = split_line_effects(effects)
    sag = jnp.asarray(0.0 if sag_guess is None else sag_guess, jnp.float64)
    yv = jnp.asarray(yv, jnp.float64)
    p, res = _static_shape(model, yv, line_eff, env, sag, max_steps)
    res = float(res)
    if not np.isfinite(res) or res > 1e-3:
        raise ValueError(
            f"static_line: no static shape found (max force residual {res:.3g} N); "
            "check that the fairleads are at most the line length apart."
        )
    return jnp.concatenate([p, jnp.zeros_like(p)], axis=1)


@eager_jit(tiered=True)
def _static_shape(model, yv, line_eff, env, sag, max_steps):
    """Newton on the still line's node forces from a parabolic guess of depth
    `sag` between the fairleads: (node positions, max |residual|)."""
    line = model.line
    still = yv.at[3:6].set(0.0).at[9:12].set(0.0)
    root, fast = model._mounts(still)
    N = line.N
    s = (jnp.arange(N) + 1.0) / (N + 1)
    straight = root.position + s[:, None] * (fast.position - root.position)
    p0 = straight.at[:, 2].add(-4.0 * sag * s * (1 - s))
    args = (line, root, fast, line_eff, env)
    return _root(_static_residual, p0, args, max_steps, 1e-12)


@eager_jit(tiered=True)
def _sag_guess(model, hawser, yv, env):
    """The parabola's sag w l0^2 / (8 T) of the line at the massless hawser's
    tension at `yv` (at least 1 kN)."""
    line = model.line
    w = (line.mass_per_length - env.rho_water * 0.25 * jnp.pi * line.d**2) * env.g
    T0 = jnp.maximum(
        hawser.tension(model.tandem, yv.reshape(2, 6)[:, :3], jnp.zeros((2, 3))), 1e3
    )
    return w * hawser.l0**2 / (8 * T0)


def line_equilibrium(scene, y_guess=None, max_steps=200):
    """The coupled equilibrium (vessels and line at rest) of a `TandemLine` scene
    nearest `y_guess` (default: the scene's `y0`), Newton (optimistix) on the full
    vector field. Returns `(y, max |residual|)`."""
    y_guess = scene.y0 if y_guess is None else jnp.asarray(y_guess, jnp.float64)
    y, res = _root(_equilibrium_residual, y_guess, scene, max_steps, 1e-11)
    return y, float(res)


HAWSER_KINDS = ("massless", "line")
LINE_OPTIONS = (
    "N",
    "d",
    "mass_per_length",
    "added_mass",
    "damping",
    "c_n",
    "c_t",
    "gravity",
)


def with_line(scene, c_n=1.0, c_t=0.1, gravity=True, name=None, **line_options):
    """The tandem `scene` with its massless `Hawser` replaced by a line of the same
    length and small-stretch stiffness (EA = k_h l0) with mass, weight, buoyancy
    and drag in the scene's current (`hawser_line`, `line_effects`; `gravity=False`
    leaves out weight and buoyancy, `c_n = c_t = 0` the drag). The vessels start
    where the scene's do; the line starts in its static shape between the
    fairleads. A controller keeps the massless hawser as its model of the line.

    `line_options`: the line's `N`, `d`, `mass_per_length`, `added_mass` and
    `damping`, as for `hawser_line` (its length and stiffness are the hawser's)."""
    from .._scene import Scene

    if not isinstance(scene.model, Tandem):
        raise ValueError("`with_line` needs a Tandem scene (with a Hawser).")
    hawsers = [e for e in scene.effects if isinstance(e, Hawser)]
    if not hawsers:
        raise ValueError("`with_line`: the scene has no `Hawser` to replace.")
    hawser = hawsers[0]
    unknown = sorted(set(line_options) - set(LINE_OPTIONS))
    if unknown:
        raise ValueError(
            f"`with_line`: unknown option(s) {unknown}; valid: {LINE_OPTIONS}."
        )
    line = hawser_line(l0=hawser.l0, k_h=hawser.k_h, **line_options)
    model = TandemLine(scene.model, line, controller_hawser=hawser)
    vessel = tuple(e for e in scene.effects if not isinstance(e, Hawser))
    eff = line_effects(c_n=c_n, c_t=c_t)
    if not gravity:
        eff = eff[2:]
    if c_n == 0.0 and c_t == 0.0:
        eff = tuple(e for e in eff if not isinstance(e, Drag))
    eff = vessel + eff
    yv = jnp.asarray(scene.y0)
    env = scene.env
    sag = _sag_guess(model, hawser, yv, env) if gravity else 0.0
    yl = static_line(model, yv, eff, env, sag_guess=sag)
    y0 = model.join(yv, yl)
    return Scene(
        model=model,
        effects=eff,
        y0=y0,
        t1=scene.t1,
        t0=scene.t0,
        name=name or scene.name + "-line",
        env=env,
    )
