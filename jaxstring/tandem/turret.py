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

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._validate import check_nonnegative
from ..lines import Body, MooringSystem, case_path, mooring_equilibrium, mooring_system
from .vessels import AbstractVesselLoad, _param, _point_load, point_kinematics


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
    c_m: Float[Array, ""] = _param(6.0e5)
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


@eqx.filter_jit
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
    f = eqx.filter_jit(lambda m, P: jax.vmap(m.restoring_force)(P))
    P = -offsets[:, None] * e[None, :]
    F = np.asarray(f(mooring, jnp.asarray(P)))
    return F @ e
