"""Effects on the string pendulum: gravity, and the constitutive laws of the string.

Two kinds of effect act on a string:

* **loads** (``AbstractStringLoad``, the one protocol of ``jaxstring.AbstractLoad``):
  ``forces(t, kin, env)`` gives external forces on the material points -- a line
  load density at the nodes (N/m of unstrained length) and a point force on the end
  mass (``Loads``); each model turns these into accelerations of its own variables.
  A load whose force does not depend on the state (``constant = True``) has the
  potential energy minus its work, which each model computes in its own
  coordinates, so that energy balances hold for each discretisation.
* **tension laws** (``AbstractTensionLaw``): the constitutive law of the string,
  applied on top of the linear elastic part N = EA eps that every string model has.
  They are applied in a fixed order (dissipation first, then the slack clip).

Gravity is the chain core's `jaxstring.chain.Gravity`, acting along -y: the
paper's pendulum swings in the x-y plane (in 3D, z is the out-of-plane direction;
`Kinematics.up`); its magnitude is the scene's ``Environment.g``.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import FloatScalar, as_array
from .._effect import AbstractEffect, AbstractLoad
from .._geometry import down
from .._validate import check_nonnegative
from ..chain import Gravity


class Kinematics(eqx.Module):
    """Positions and velocities of the material points of a string, and their masses.

    **Arguments:**

    - `positions`: node positions including the pivot, shape `(k + 1, dim)`, m.
    - `velocities`: node velocities, shape `(k + 1, dim)`, m/s. The last node is the
      end mass.
    - `line_mass`: mass per unstrained length mu, kg/m.
    - `end_mass`: the end mass m_s, kg.
    """

    positions: Float[Array, "n dim"]
    velocities: Float[Array, "n dim"]
    line_mass: FloatScalar
    end_mass: FloatScalar

    @property
    def up(self):
        """The upward unit vector, +y (the pendulum swings in the x-y plane)."""
        return -down(self.positions.shape[-1])

    @property
    def masses(self) -> "Loads":
        """Mass per unstrained length at the nodes and the end mass, in the layout
        of the loads."""
        n = self.positions.shape[0]
        return Loads(line=jnp.broadcast_to(self.line_mass, (n, 1)), end=self.end_mass)


class Loads(eqx.Module):
    """External loads: a line density at the nodes and a force on the end mass.

    - `line`: shape `(k + 1, dim)`, N per m of unstrained length.
    - `end`: shape `(dim,)`, N, acting on the end mass.
    """

    line: Float[Array, "n dim"]
    end: Float[Array, " dim"]

    def __add__(self, other: "Loads") -> "Loads":
        return Loads(self.line + other.line, self.end + other.end)


class AbstractStringLoad(AbstractLoad):
    """A load on the string: `forces(t, kin, env) -> Loads`.

    `constant`: True when the force depends on neither the state nor time (its
    potential is then minus its work)."""

    constant: ClassVar[bool] = False

    @abc.abstractmethod
    def forces(self, t, kin: Kinematics, env) -> Loads:
        """Return the loads at time `t` (s) on the string with kinematics `kin`."""


class AbstractTensionLaw(AbstractEffect):
    """An effect that changes the axial force law N(eps, eps_dot) of the string."""

    order: ClassVar[int]

    @abc.abstractmethod
    def tension(self, N, eps, eps_dot, EA):
        """Return the axial force after this law, given the force `N` before it (N)."""

    @abc.abstractmethod
    def elastic_strain(self, eps):
        """Return the strain that stores elastic energy EA/2 eps^2 under this law."""


class KelvinVoigt(AbstractTensionLaw):
    """Kelvin-Voigt internal dissipation: N = EA (eps + alpha d(eps)/dt) (paper eq 2).

    **Arguments:**

    - `alpha`: dissipation constant, s (>= 0).
    """

    alpha: FloatScalar = eqx.field(converter=as_array, default=0.01)
    order: ClassVar[int] = 0

    def __check_init__(self):
        check_nonnegative("alpha", self.alpha, "s")

    def tension(self, N, eps, eps_dot, EA):
        del eps
        return N + EA * self.alpha * eps_dot

    def elastic_strain(self, eps):
        return eps


class Slack(AbstractTensionLaw):
    """Tension-only string: no compression, and no force at all while slack.

    Sharp law (`smoothing=0`): N = max(N, 0) where eps > 0, and N = 0 where
    eps <= 0 (the string cannot push, and a slack string carries no dissipative
    force either, as in MoorDyn); stored elastic energy EA/2 max(eps, 0)^2.

    Smoothed law (`smoothing` = eps_s > 0): the onset of tension is blended over
    the strains [0, eps_s], so that the force is continuously differentiable:

        N = EA g(eps / eps_s) eps_s r(N_in / (EA eps_s)),

    with z clipped to [0, 1], the gate g(z) = 3 z^2 - 2 z^3 and the ramp
    r(z) = 2 z^2 - z^3 for z < 1, r(z) = z above (N_in: the force before this law,
    EA (eps + alpha eps') under Kelvin-Voigt). A compressed string (eps <= 0) and a
    pushing one (N_in <= 0) carry no force, exactly as under the sharp law; at
    eps >= eps_s with N_in >= EA eps_s the force is the sharp law's. In between it
    is smaller, never negative: for an elastic string by at most 0.317 EA eps_s
    (max of z - g(z) r(z), at z = 0.456); for a string snapping taut, the viscous
    force EA alpha eps' is also cut while eps < eps_s, an impulse of at most
    EA alpha eps_s per element and monotone crossing of the blend. Stored elastic
    energy: EA eps_s^2 (6 z^5/5 - 7 z^6/6 + 2 z^7/7) below eps_s,
    EA (eps^2/2 - 19/105 eps_s^2) above.

    The sharp law's kinks (zero strain, zero force), on which the elements of a
    falling slack string sit, make error-controlled implicit solvers in natural
    variables reject steps down to tiny sizes; eps_s = 1e-7 is the pendulum scene's
    default in natural variables (what it does to the steps and the end mass:
    docs/pendulum.md, "Slack and snap").

    **Arguments:**

    - `smoothing`: the transition strain eps_s (>= 0, dimensionless; 0: the sharp
      law).
    """

    smoothing: float = eqx.field(static=True, default=0.0)
    order: ClassVar[int] = 10

    def __check_init__(self):
        check_nonnegative("smoothing", self.smoothing)

    def tension(self, N, eps, eps_dot, EA):
        del eps_dot
        w = self.smoothing
        if w == 0:
            return jnp.where(eps > 0, jnp.maximum(N, 0.0), 0.0)
        z = jnp.clip(eps / w, 0.0, 1.0)
        gate = z * z * (3.0 - 2.0 * z)
        scale = EA * w
        zu = jnp.clip(N / scale, 0.0, 1.0)
        return gate * jnp.where(N < scale, scale * zu * zu * (2.0 - zu), N)

    def elastic_strain(self, eps):
        w = self.smoothing
        if w == 0:
            return jnp.maximum(eps, 0.0)
        # The strain e with EA e^2 / 2 = the energy stored at eps (see above).
        z = jnp.clip(eps / w, 0.0, 1.0)
        blend = w * w * z**5 * (6.0 / 5.0 - 7.0 / 6.0 * z + 2.0 / 7.0 * z * z)
        two_w = jnp.where(eps < w, 2.0 * blend, eps * eps - 38.0 / 105.0 * w * w)
        positive = two_w > 0
        return jnp.where(positive, jnp.sqrt(jnp.where(positive, two_w, 1.0)), 0.0)


EFFECTS = {
    "gravity": Gravity,
    "kelvin_voigt": KelvinVoigt,
    "slack": Slack,
}


def split_effects(effects):
    """Split effects into (loads, tension laws sorted by their order)."""
    loads = tuple(e for e in effects if isinstance(e, AbstractLoad))
    laws = tuple(
        sorted(
            (e for e in effects if isinstance(e, AbstractTensionLaw)),
            key=lambda e: e.order,
        )
    )
    return loads, laws


def total_loads(loads, t, kin, env) -> Loads:
    """Sum the loads of all load effects (zero when there are none)."""
    total = Loads(
        line=jnp.zeros_like(kin.positions), end=jnp.zeros_like(kin.positions[-1])
    )
    for effect in loads:
        total = total + effect.forces(t, kin, env)
    return total


def apply_laws(laws, EA, eps, eps_dot):
    """Axial force from the elastic law N = EA eps and then each tension law."""
    N = EA * eps
    for law in laws:
        N = law.tension(N, eps, eps_dot, EA)
    return N


def elastic_strain(laws, eps):
    for law in laws:
        eps = law.elastic_strain(eps)
    return eps
