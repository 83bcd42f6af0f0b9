"""Physical effects a scene may call for.

An effect that a scene does not name is not part of the scene: it is never traced
and adds no operation to the compiled vector field. Switching an effect "off" is
always structural (leave it out of ``Scene.effects``), never a traced flag.

Two kinds of effect act on a string:

* **loads** (``AbstractLoad``): external forces on material points -- a line load
  density at the nodes (N/m of unstrained length) and a point force on the end mass;
  each model turns these into accelerations of its own variables. Conservative loads
  also give their potential energy so that energy balances can be checked.
* **tension laws** (``AbstractTensionLaw``): the constitutive law of the string,
  applied on top of the linear elastic part N = EA eps that every string model has.
  They are applied in a fixed order (dissipation first, then the slack clip).
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._geometry import down
from .._validate import check_nonnegative


class Kinematics(eqx.Module):
    """Positions and velocities of the material points of a string.

    **Arguments:**

    - `positions`: node positions including the pivot, shape `(k + 1, dim)`, m.
    - `velocities`: node velocities, shape `(k + 1, dim)`, m/s. The last node is the
      end mass.
    """

    positions: Float[Array, "n dim"]
    velocities: Float[Array, "n dim"]


class Loads(eqx.Module):
    """External loads: a line density at the nodes and a force on the end mass.

    - `line`: shape `(k + 1, dim)`, N per m of unstrained length.
    - `end`: shape `(dim,)`, N, acting on the end mass.
    """

    line: Float[Array, "n dim"]
    end: Float[Array, " dim"]

    def __add__(self, other: "Loads") -> "Loads":
        return Loads(self.line + other.line, self.end + other.end)


class AbstractEffect(eqx.Module):
    """Base of all effects."""


class AbstractLoad(AbstractEffect):
    """An effect that applies external forces to the material points."""

    @abc.abstractmethod
    def loads(self, t, kin: Kinematics, model) -> Loads:
        """Return the loads at time `t` (s) for kinematics `kin` of `model`."""

    @abc.abstractmethod
    def potential(self, y, kin: Kinematics, model) -> Float[Array, ""]:
        """Return the potential energy of the load (J) in state `y` (with kinematics
        `kin`); 0 for a non-conservative load."""


class AbstractTensionLaw(AbstractEffect):
    """An effect that changes the axial force law N(eps, eps_dot) of the string."""

    order: ClassVar[int]

    @abc.abstractmethod
    def tension(self, N, eps, eps_dot, EA):
        """Return the axial force after this law, given the force `N` before it (N)."""

    @abc.abstractmethod
    def elastic_strain(self, eps):
        """Return the strain that stores elastic energy EA/2 eps^2 under this law."""


class Gravity(AbstractLoad):
    """Uniform gravity along -y: weight of the string (mu g) and of the end mass.

    **Arguments:**

    - `g`: gravitational acceleration, m/s^2 (>= 0).
    """

    g: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=9.81)

    def __check_init__(self):
        check_nonnegative("g", self.g, "m/s^2")

    def loads(self, t, kin, model):
        del t
        gvec = self.g * down(kin.positions.shape[-1])
        line = jnp.broadcast_to(model.mu * gvec, kin.positions.shape)
        return Loads(line=line, end=model.m_s * gvec)

    def potential(self, y, kin, model):
        # Gravity is a constant load: its potential is minus its work in the
        # model's own generalised coordinates (so that energy balances hold exactly
        # for each discretisation).
        return model.constant_load_potential(y, self.loads(0.0, kin, model))


class KelvinVoigt(AbstractTensionLaw):
    """Kelvin-Voigt internal dissipation: N = EA (eps + alpha d(eps)/dt) (paper eq 2).

    **Arguments:**

    - `alpha`: dissipation constant, s (>= 0).
    """

    alpha: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.01)
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

    N = max(N, 0) where eps > 0, and N = 0 where eps <= 0 (the string cannot push,
    and a slack string carries no dissipative force either, as in MoorDyn). Stores
    elastic energy EA/2 max(eps, 0)^2.
    """

    order: ClassVar[int] = 10

    def tension(self, N, eps, eps_dot, EA):
        del eps_dot, EA
        return jnp.where(eps > 0, jnp.maximum(N, 0.0), 0.0)

    def elastic_strain(self, eps):
        return jnp.maximum(eps, 0.0)


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


def total_loads(loads, t, kin, model) -> Loads:
    """Sum the loads of all load effects (zero when there are none)."""
    total = Loads(
        line=jnp.zeros_like(kin.positions), end=jnp.zeros_like(kin.positions[-1])
    )
    for effect in loads:
        total = total + effect.loads(t, kin, model)
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
