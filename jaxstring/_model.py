"""The interface every jaxstring model implements (strings, tethers, vessels)."""

import abc
from typing import ClassVar

import equinox as eqx
from jaxtyping import Array


class AbstractModel(eqx.Module):
    """A model: state layout, internal physics, and observables.

    Array fields are physical parameters (differentiable, vmappable); static fields
    are structure. Subclasses implement:

    - `accepts`: the effect kinds (base classes) the model knows how to apply; a
      `Scene` refuses any other effect with a ValueError naming both.
    - `state_shape()`: the shape of the state array `y`.
    - `vector_field(t, y, effects, env)`: dy/dt under the scene's effects in the
      scene's `Environment`.
    - `observables(t, y, effects, env)`: a dict of derived quantities of one state
      (e.g. `positions`, `tension`, `energy`), saved in the Trajectory.
    - `project(y)`: the nearest state on the model's constraint manifold (identity
      for unconstrained models); `simulate` applies it after every step when
      `projects` is True.
    """

    accepts: ClassVar[tuple[type, ...]] = ()

    @abc.abstractmethod
    def state_shape(self) -> tuple[int, ...]:
        """Shape of the state array."""

    @abc.abstractmethod
    def vector_field(self, t, y, effects, env) -> Array:
        """dy/dt of state `y` at time `t` (s) under `effects` in environment `env`."""

    @abc.abstractmethod
    def observables(self, t, y, effects, env) -> dict:
        """Derived quantities of one state, as a dict of arrays."""

    @property
    @abc.abstractmethod
    def projects(self) -> bool:
        """Whether `project` is a non-trivial projection to apply after each step."""

    @abc.abstractmethod
    def project(self, y) -> Array:
        """The nearest state on the constraint manifold."""

    def node_bandwidth(self, effects) -> int | None:
        """The node bandwidth of the Jacobian of `vector_field` under `effects`, if
        the model knows it (node-major state `(n, b)` where node i couples to nodes
        i - w ... i + w), else None. Implicit solvers then skip detecting the band
        by probing (`jaxstring._linalg.detect_width`), which costs an extra XLA
        compilation at trace time. Default: None (detect)."""
        del effects
        return None

    def second_order(self, effects) -> int:
        """d > 0 if every node row of the state is (q, v), d components each, and
        `vector_field` returns exactly v as dq/dt under `effects`. The implicit
        solvers then reduce each banded Newton system to the velocities
        (`jaxstring._linalg.SecondOrderFactor`: blocks of d instead of 2 d).
        Default: 0 (no such layout)."""
        del effects
        return 0

    def stage_jacobians(self, effects) -> bool:
        """Whether an implicit Runge-Kutta step (Kvaerno) should take a fresh
        Jacobian at each implicit stage's predictor rather than one per step.

        True where the stiff forces turn with the state, so that a Jacobian from
        the step's first stage no longer contracts the later stages' Newton
        iterations (stiff springs between moving nodes: the displacement string,
        the lumped-mass tether). False (the default) where the stiff part is
        (nearly) linear in the state, as in natural variables, where the extra
        factorisations would only cost time."""
        del effects
        return False

    def step_jacobians(self, effects) -> bool:
        """Whether a multistep method (BDF) should take a fresh Jacobian at every
        step rather than keep one across steps.

        True where the stiff directions turn so fast with the state that a
        Jacobian from the previous step does not contract the Newton iteration
        (the displacement string swinging: 0.07 % of its steps converged with the
        stored one); BDF then carries no factorisation at all. False (the default)
        where a stored Jacobian serves many steps: natural variables, and mooring
        chains moving slowly (MoorDyn's chain cases: BDF 1.3-1.8x faster keeping
        it)."""
        del effects
        return False

    def vf_jacobian(self, t, y, effects, env):
        """The Jacobian of `vector_field` at `(t, y)` as a
        `jaxstring._linalg.BlockTridiagonal` (one node per block), if the model can
        build it more cheaply than the implicit solvers' coloured JVPs (3 b of them
        for b components a node), else None. Default: None.

        A model that returns a matrix must return the exact Jacobian under
        `effects` (tests/test_fast_solvers.py compares it with the JVP-built one)
        and None for any effect it does not know."""
        del t, y, effects, env
        return None
