"""The FPSO's turret on catenary mooring lines (quasi-static), in place of the
spec's hardening spring (spec 3.4).

A MoorDyn deck read by `jaxstring.lines` gives the lines: fixed anchors, free
points (e.g. the chain-wire connections of chain/wire/chain legs) and the
fairleads, the deck's Vessel (coupled) points, which become points on a coupled
turret body at the deck's origin. The turret follows the FPSO's turret point
horizontally and keeps its heading (the bearing lets the vessel weathervane
about it; the lines do not turn with the hull); heave, roll and pitch are not
modelled (the tandem is a horizontal-plane model), so the turret stays at the
deck's depth.

At each turret offset $P_T$ (earth axes, the deck's x, y taken as the tandem's
x north, y east; the deck's origin is the earth origin) the free points are
re-balanced (`jaxstring.lines.mooring_equilibrium` with the turret's offsets)
and the horizontal force of the lines on the turret is the restoring force:

    F_T = F_lines(P_T) - c_m V_T      (earth axes; moment x_t f_y on the hull)

`c_m` is the spec's linear turret damping (the quasi-static lines give none).
Every derivative is exact (the statics' implicit differentiation), so the
equilibria's Jacobian eigenvalues and gradients go through the lines. Where the
statics find no equilibrium (an offset the lines cannot hold, a line sagging onto
the seabed between its ends) the force is NaN, so a solver or an integrator
fails visibly rather than silently.
"""

import dataclasses
import os
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._arrays import FloatScalar
from .._jit import cpu_jit
from .._model import AbstractModel, SolverStructure
from .._validate import check_nonnegative
from ..chain import AbstractEnd, EndKinematics
from ..lines import (
    Body,
    LineNetwork,
    MooringSystem,
    case_path,
    mooring_equilibrium,
    mooring_system,
)
from .vessels import (
    AbstractActuator,
    AbstractVesselLoad,
    _param,
    _point_load,
    point_kinematics,
)


TURRET_DECK = "turret_fpso.txt"


class TurretLines(AbstractVesselLoad):
    """Turret mooring of the FPSO (vessel 1) on quasi-static catenary lines.

    **Arguments:**

    - `system`: a `jaxstring.lines.MooringSystem` with one coupled body, the
      turret, whose reference point is the turret's centre at zero offset (build
      it with `turret_lines`).
    - `c_m`: linear turret damping, N s/m (spec 3.4's 6e5 by default).
    - `tol` (static): the statics' residual tolerance relative to the force scale
      (1e-8: kilometre-long legs of stiff chain reach round-off near 1e-10).
    """

    system: MooringSystem
    c_m: FloatScalar = _param(6.0e5)
    tol: float = eqx.field(static=True, default=1e-8)

    def __check_init__(self):
        if not isinstance(self.system, MooringSystem):
            raise ValueError(
                "`system` must be a jaxstring.lines.MooringSystem; got "
                f"{type(self.system).__name__}."
            )
        kinds = [b.kind for b in self.system.bodies]
        if kinds != ["coupled"]:
            raise ValueError(
                "`system` must have exactly one body, the coupled turret; got "
                f"bodies of kinds {kinds}."
            )
        check_nonnegative("c_m", self.c_m, "N s/m")
        if not 0.0 < self.tol < 1e-3:
            raise ValueError(f"`tol` must lie in (0, 1e-3); got {self.tol!r}.")

    def equilibrium(self, P):
        """The lines' `MooringEquilibrium` with the turret at horizontal offset `P`
        (m, earth axes, shape (2,))."""
        P = jnp.asarray(P, jnp.float64)
        offsets = jnp.concatenate([P, jnp.zeros(4, P.dtype)])
        return mooring_equilibrium(
            self.system, offsets=offsets, tol=self.tol, throw=False
        )

    def restoring_force(self, P):
        """The lines' horizontal force on the turret at offset `P` (N, earth axes,
        shape (2,)); NaN where the statics find no equilibrium."""
        eq = self.equilibrium(P)
        return jnp.where(eq.status == 0, eq.coupled_force[:2], jnp.nan)

    def forces(self, t, kin, env):
        del t, env
        model, eta, nu = kin.vessels, kin.eta, kin.nu
        P, V = point_kinematics(eta[0], nu[0], model.x_t)
        F = self.restoring_force(P) - self.c_m * V
        out = jnp.zeros_like(eta)
        return out.at[0].set(_point_load(eta[0], F, model.x_t))

    def offset_for_force(self, F, heading=0.0):
        """The offset r (m) of the turret along minus the unit vector e of
        `heading` (rad) at which the lines' force along e balances a load `F` (N)
        pushing the turret that way: e . F_lines(-r e) = F (the secant method on
        the lines' force alone; the spring's `_mooring_offset` counterpart, for
        the aligned starts)."""
        return _offset_for_force(self, jnp.asarray(F, jnp.float64),
                                 jnp.asarray(heading, jnp.float64))  # fmt: skip


@cpu_jit(tiered=True)
def _restoring_forces(lines: TurretLines, P):
    return jax.vmap(lines.restoring_force)(P)


@cpu_jit(tiered=True)
def _offset_for_force(lines: TurretLines, F, heading):
    e = jnp.stack([jnp.cos(heading), jnp.sin(heading)])

    def g(r):
        return jnp.dot(e, lines.restoring_force(-r * e)) - F

    def body(_, c):
        r0, g0, r1, g1 = c
        d = g1 - g0
        ok = (d != 0) & jnp.isfinite(d)
        r2 = jnp.where(ok, r1 - g1 * (r1 - r0) / jnp.where(ok, d, 1.0), r1)
        return r1, g1, r2, g(r2)

    r1 = jnp.where(F >= 0, 1.0, -1.0)
    c = (jnp.zeros_like(F), -F, r1, g(r1))
    return jax.lax.fori_loop(0, 15, body, c)[2]


def turret_lines(
    deck=None, c_m=6.0e5, tol=1e-8, depth=None, g=None, rho=None
) -> TurretLines:
    """The FPSO's turret moored on the lines of a MoorDyn deck.

    **Arguments:**

    - `deck`: a `MoorDynDeck`, the path of a deck, or None: the packaged example
      (`jaxstring.lines.case_path("turret_fpso.txt")`: nine chain/wire/chain legs
      of a VLCC-size FPSO in 1000 m of water; its header says where its numbers
      come from). The deck's Vessel (coupled) points are the fairleads on the
      turret, relative to its centre at the deck's origin.
    - `c_m`: linear turret damping, N s/m (>= 0). `tol`: as `TurretLines`.
    - `depth`, `g`, `rho`: override the deck's (see `mooring_system`).

    **Returns:** a `TurretLines` load (a scene effect in place of `TurretMooring`).
    """
    if deck is None:
        deck = case_path(TURRET_DECK)
    turret = Body("coupled", position=[0.0, 0.0, 0.0], name="turret")
    system = mooring_system(deck, vessel=turret, depth=depth, g=g, rho=rho)
    on_turret = [p for p in system.points if p.kind == "body"]
    if not on_turret:
        raise ValueError(
            f"`deck` {deck!r} has no Vessel/Coupled points (fairleads on the turret); "
            "got none, so nothing holds the FPSO."
        )
    return TurretLines(system=system, c_m=c_m, tol=tol)


def offset_force_curve(mooring, offsets, heading=0.0):
    """The restoring force along minus `heading` (N) at turret offsets `offsets`
    (m) along that direction, for a `TurretLines` or a `TurretMooring` (the
    spec's spring, k_m (1 + r^2/rho_m^2) r): the offset-force curve.

    The lines' force is evaluated at each offset eagerly (one compile)."""
    from .vessels import TurretMooring

    offsets = np.asarray(offsets, float)
    e = np.array([np.cos(heading), np.sin(heading)])
    if isinstance(mooring, TurretMooring):
        k, rho = float(mooring.k_m), float(mooring.rho_m)
        return k * (1.0 + offsets**2 / rho**2) * offsets
    if not isinstance(mooring, TurretLines):
        raise ValueError(
            "`mooring` must be a TurretLines or a TurretMooring; got "
            f"{type(mooring).__name__}."
        )
    P = -offsets[:, None] * e[None, :]
    F = np.asarray(_restoring_forces(mooring, jnp.asarray(P)))
    return F @ e


# ---------------------------------------------------------------------------
# Dynamic lines: the mooring integrated with the vessels


class _TurretFairlead(AbstractEnd):
    """A fairlead on the turret: at `position` with `velocity` (earth axes, m,
    m/s) and no acceleration (the end node's inertia at the turret's
    acceleration is left out; see `MooredVessels`)."""

    position: Float[Array, "3"]
    velocity: Float[Array, "3"]

    def kinematics(self, t):
        del t
        return EndKinematics(self.position, self.velocity, jnp.zeros(3))


def split_mooring_effects(effects):
    """(vessel effects, line effects) of a `MooredVessels` scene; raises on an
    effect that belongs to neither or on a turret mooring effect (the lines are
    the mooring)."""
    from .vessels import TurretMooring

    vessel, line = [], []
    for e in effects:
        if isinstance(e, (TurretMooring, TurretLines)):
            raise ValueError(
                "a MooredVessels scene must not name a turret mooring effect "
                f"({type(e).__name__}): its lines are the mooring."
            )
        if isinstance(e, (AbstractVesselLoad, AbstractActuator)):
            vessel.append(e)
        elif isinstance(e, LineNetwork.accepts):
            line.append(e)
        else:
            raise ValueError(
                "a MooredVessels scene takes vessel loads, one actuator and the "
                "lines' loads (Gravity, Buoyancy, Drag, Seabed); got "
                f"{type(e).__name__} in `effects`."
            )
    return tuple(vessel), tuple(line)


class MooredVessels(AbstractModel):
    r"""The FPSO (alone or in the tandem) on a turret held by lumped-mass lines
    integrated with the vessels: the dynamic counterpart of `TurretLines`.

    State: `(n_vessels + n, 6)`, one row per vessel (x, y, psi, u, v, r), then
    the line network's n rows; the Jacobian is the network's band with the
    vessels' rows as its border (`SolverStructure.border`). The fairleads (the
    deck's Vessel points, relative to the turret's centre) follow the FPSO's
    turret point horizontally at the deck's depth and keep the deck's heading
    (the bearing, as in `TurretLines`). The lines' forces on the fairleads,
    summed, act on the FPSO at the turret (horizontal part; the 3-DOF hulls have
    no heave), with the optional linear damping `c_m`.

    The line network's end nodes are held by the fairleads; their inertia at the
    turret's acceleration is not fed back (the nodes next to the turret weigh a
    few tonnes, the FPSO with its added mass about 4e8 kg), so the coupling needs
    no second pass.

    **Arguments:**

    - `vessels`: a `Tandem` or a `MooredFPSO`.
    - `network`: a `jaxstring.lines.LineNetwork` whose points `fairleads` are the
      turret's (any held end; their positions are taken relative to the turret's
      centre at the origin).
    - `fairleads` (static): indices of the fairleads in `network.points`.
    - `c_m`: linear turret damping, N s/m (>= 0; default 0: the lines' drag and
      internal damping are the mooring's damping).
    - `current` (static): the lines feel the scene's current (True) or lie in
      still water (False, default).
    """

    vessels: AbstractModel
    network: LineNetwork
    fairleads: tuple = eqx.field(static=True)
    c_m: FloatScalar = _param(0.0)
    current: bool = eqx.field(static=True, default=False)
    projects: ClassVar[bool] = False
    accepts: ClassVar[tuple[type, ...]] = LineNetwork.accepts + (
        AbstractVesselLoad,
        AbstractActuator,
    )

    def __check_init__(self):
        from .vessels import MooredFPSO, Tandem

        if not isinstance(self.vessels, (Tandem, MooredFPSO)):
            raise ValueError(
                "`vessels` must be a Tandem or a MooredFPSO; got "
                f"{type(self.vessels).__name__}."
            )
        if not isinstance(self.network, LineNetwork):
            raise ValueError(
                "`network` must be a jaxstring.lines.LineNetwork; got "
                f"{type(self.network).__name__}."
            )
        n = len(self.network.points)
        if not self.fairleads or not all(
            isinstance(i, int)
            and 0 <= i < n
            and isinstance(self.network.points[i], AbstractEnd)
            for i in self.fairleads
        ):
            raise ValueError(
                f"`fairleads` must name held points of `network` (indices in "
                f"0..{n - 1}); got {self.fairleads!r}."
            )
        if self.network.bodies or self.network.rods:
            raise ValueError(
                "`network` must hold lines and points only (the turret carries the "
                "fairleads); got bodies or rods."
            )
        check_nonnegative("c_m", self.c_m, "N s/m")

    def state_shape(self):
        return (self.vessels.n_vessels + self.network.topology.n_state, 6)

    def project(self, y):
        return y

    def structure(self, effects):
        """The network's band after one border row per vessel (the vessels couple
        to the fairleads' neighbours, wherever the band puts them)."""
        net = self.network.structure(effects)
        return SolverStructure(
            bandwidth=net.bandwidth,
            second_order=net.second_order,
            stage_jacobians=True,
            border=self.vessels.n_vessels,
        )

    def split(self, y):
        """(vessel state `(6 n_vessels,)`, line state `(n, 6)`)."""
        k = self.vessels.n_vessels
        return y[:k].reshape(-1), y[k:]

    def join(self, yv, yl):
        return jnp.concatenate([jnp.reshape(yv, (-1, 6)), yl])

    def moved(self, P, V):
        """The network with its fairleads at turret offset `P` moving at `V` (m,
        m/s, earth axes, shape (2,))."""
        z = jnp.zeros(1, P.dtype)
        dP, dV = jnp.concatenate([P, z]), jnp.concatenate([V, z])
        points = list(self.network.points)
        for i in self.fairleads:
            p0 = self.network.points[i].kinematics(0.0).position
            points[i] = _TurretFairlead(p0 + dP, dV)
        return eqx.tree_at(lambda n: n.points, self.network, tuple(points))

    def line_env(self, env):
        """The lines' environment: the scene's, in still water unless `current`."""
        if self.current or env.current is None:
            return env
        return eqx.tree_at(lambda e: e.current, env, None, is_leaf=lambda x: x is None)

    def _parts(self, t, y, effects, env):
        from .vessels import _actuator, _rhs, saturated_command

        vessel, line_eff = split_mooring_effects(effects)
        yv, yl = self.split(y)
        s = yv.reshape(-1, 6)
        x_t = self.vessels.x_t
        P, V = point_kinematics(s[0, :3], s[0, 3:], x_t)
        net = self.moved(P, V)
        env_l = self.line_env(env)
        st = net._state(t, yl, line_eff, env_l)
        dyl, acc, _, _ = net._rates(t, yl, st, line_eff, env_l)
        fa, fb = net.end_forces(st, acc)
        ia = [k for k, (a, _) in enumerate(net.attach) if a in self.fairleads]
        ib = [k for k, (_, b) in enumerate(net.attach) if b in self.fairleads]
        F = fa[jnp.asarray(ia, int)].sum(0) + fb[jnp.asarray(ib, int)].sum(0)
        n = self.vessels.n_vessels
        F_h = F[:2] - self.c_m * V
        extra = jnp.zeros((n, 3), y.dtype).at[0].set(_point_load(s[0, :3], F_h, x_t))
        act = _actuator(vessel)
        u = None
        if act is not None:
            u = saturated_command(act, t, yv, self.vessels, vessel, env)
        dyv = _rhs(self.vessels, t, yv, vessel, env, u, extra)
        tension = jnp.sqrt(jnp.sum(jnp.concatenate([fa[jnp.asarray(ia, int)],
                                                    fb[jnp.asarray(ib, int)]]) ** 2,
                                   axis=1))  # fmt: skip
        return dyv, dyl, F, P, tension

    def vector_field(self, t, y, effects, env):
        dyv, dyl, *_ = self._parts(t, y, effects, env)
        return self.join(dyv, dyl)

    def observables(self, t, y, effects, env):
        """The vessels' observables, plus `turret_force` (the lines' horizontal
        force on the turret, N, (2,)), `turret_offset` (m), `fairlead_tensions`
        (each fairlead line's force, N) and the line network's `nodes` (m)."""
        vessel, _ = split_mooring_effects(effects)
        yv, yl = self.split(y)
        _, _, F, P, tension = self._parts(t, y, effects, env)
        out = dict(self.vessels.observables(t, yv, vessel, env))
        out.update(
            turret_force=F[:2],
            turret_offset=jnp.sqrt(jnp.sum(P * P)),
            fairlead_tensions=tension,
            nodes=yl[:, :3],
        )
        return out


def with_dynamic_mooring(
    scene, deck=None, segments=None, c_m=0.0, current=False, name=None
):
    """The tandem or FPSO-alone `scene` with its turret mooring replaced by the
    lines of a MoorDyn deck integrated with the vessels (`MooredVessels`).

    **Arguments:**

    - `deck`: a `MoorDynDeck`, a deck's path, or None: the packaged turret deck
      (as `turret_lines`). Lines and points only; its Vessel points are the
      fairleads on the turret.
    - `segments`: segments per line (int >= 1), or None (default): the deck's.
    - `c_m`: linear turret damping, N s/m (default 0: the lines damp).
    - `current`: the lines feel the scene's current (True) or lie in still water
      (default, as the quasi-static lines and the spring). The tandem scenes'
      current is uniform over the depth: on the packaged deck's 1000 m legs it
      would push the turret far harder than the hulls' own current load.

    The vessels start where the scene's do; the lines start at their static
    equilibrium (free points included, in the current when `current`) with the
    fairleads at the scene's turret offset. The scene's environment (gravity,
    water density) replaces the deck's.

    **Returns:** a `Scene` (the model a `MooredVessels`; solve it with an
    implicit solver, the lines are stiff).
    """
    from .._scene import Scene
    from .._validate import check_int
    from ..lines import MoorDynDeck, deck_scene, equilibrium, parse_moordyn
    from .vessels import MooredFPSO, Tandem, TurretMooring

    if not isinstance(scene.model, (Tandem, MooredFPSO)):
        raise ValueError(
            "`with_dynamic_mooring` needs a tandem or FPSO-alone scene (its model a "
            f"Tandem or a MooredFPSO); got {type(scene.model).__name__}."
        )
    if segments is not None:
        check_int("segments", segments, 1)
    check_nonnegative("c_m", c_m, "N s/m")
    if deck is None:
        deck = case_path(TURRET_DECK)
    if isinstance(deck, (str, os.PathLike)):
        deck = parse_moordyn(deck)
    if not isinstance(deck, MoorDynDeck):
        raise ValueError(
            f"`deck` must be a MoorDynDeck, a path or None; got {type(deck).__name__}."
        )
    if deck.bodies or deck.rods:
        raise ValueError(
            f"`deck` {deck.path!r} must hold lines and points only (the turret "
            "carries the fairleads); it has bodies or rods."
        )
    if segments is not None:
        lines = [dict(ln, segments=segments) for ln in deck.lines]
        deck = dataclasses.replace(deck, lines=lines)
    fairleads = tuple(i for i, p in enumerate(deck.points) if p["kind"] == "coupled")
    if not fairleads:
        raise ValueError(
            f"`deck` {deck.path!r} has no Vessel/Coupled points (fairleads on the "
            "turret); got none, so nothing holds the FPSO."
        )
    lines_scene = deck_scene(deck, static=False)
    network = lines_scene.model  # the fairleads FixedEnds at the deck's positions
    vessel = tuple(
        e for e in scene.effects if not isinstance(e, (TurretMooring, TurretLines))
    )
    effects = vessel + tuple(lines_scene.effects)
    model = MooredVessels(
        vessels=scene.model,
        network=network,
        fairleads=fairleads,
        c_m=c_m,
        current=current,
    )
    yv = jnp.asarray(scene.y0, jnp.float64)
    s = yv.reshape(-1, 6)
    P, _ = point_kinematics(s[0, :3], s[0, 3:], scene.model.x_t)
    held = model.moved(P, jnp.zeros(2))
    _, line_eff = split_mooring_effects(effects)
    yl, _ = equilibrium(
        held, line_eff, model.line_env(scene.env), scene.t0, free_points="solve"
    )
    return Scene(
        model=model,
        effects=effects,
        y0=model.join(yv, yl),
        t1=scene.t1,
        t0=scene.t0,
        name=name or scene.name + "-dynamic-lines",
        env=scene.env,
    )
