"""The one effect protocol.

An effect is one piece of physics a scene calls for. An effect that a scene does not
name is not part of the scene: it is never traced and adds no operation to the
compiled vector field ("off" is always structural, never a traced flag).

Every load effect maps `(t, kinematics, environment)` to forces on the material
points of a model:

    forces = effect.forces(t, kin, env)

`kin` is the model's kinematics: positions and velocities of its material points and
the material properties the effects read (masses, volumes, diameters, hull
coefficients). The model turns the forces into accelerations of its own variables.
A load that depends on neither the state nor time declares `constant = True`: its
potential energy is then minus its work, which the model computes in its own
coordinates, so that energy balances can be tested for every discretisation.

Each model declares the effect kinds it accepts (`AbstractModel.accepts`); a scene
that names any other effect is refused with a ValueError naming both.
"""

import abc
from typing import ClassVar

import equinox as eqx


class AbstractEffect(eqx.Module):
    """Base of every effect (loads, constitutive laws, actuators)."""


class AbstractLoad(AbstractEffect):
    """An effect that applies external forces to a model's material points."""

    constant: ClassVar[bool] = False

    @abc.abstractmethod
    def forces(self, t, kin, env):
        """Forces at time `t` (s) on the material points described by `kin`, in the
        environment `env`; the layout is the model's (see its kinematics class)."""
