"""The interface every jaxstring model implements (strings, tethers, vessels)."""

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
from jaxtyping import Array


@dataclasses.dataclass(frozen=True)
class SolverStructure:
    """What a model tells the implicit solvers about its vector field.

    **Fields** (all structure, none traced: plain Python values):

    - `bandwidth`: w when the state is node-major `(n, b)` and node i couples only
      to nodes i - w ... i + w; None: the solvers detect the band by probing (one
      extra compilation at trace time).
    - `second_order`: d > 0 when every node row is (q, v) with d components each
      and `vector_field` returns exactly v as dq/dt: Newton systems are then
      reduced to the velocities (blocks of d instead of 2 d). 0: no such layout.
    - `stage_jacobians`: an implicit Runge-Kutta step (Kvaerno) takes a fresh
      Jacobian at each implicit stage instead of one per step -- for models whose
      stiff directions turn with the state within a step (stiff springs between
      moving nodes); one per step serves where the stiff part is nearly linear in
      the state (natural variables).
    - `step_jacobians`: a multistep method (BDF) takes a fresh Jacobian every step
      instead of keeping one across steps, for the same reason.
    - `jacobian`: the model's `vf_jacobian` gives the exact Jacobian (cheaper than
      coloured JVPs).
    - `border`: k > 0 when the first k node rows couple to every row (a vessel
      holding lines) and the other rows form a band of node width `bandwidth`
      (`second_order` then describes those rows): the Newton matrices are
      factorised by the band's Schur complement (`jaxstring._linalg`).
    - `border_coupled`: with a `border`, the rows after it that the border's
      rows depend on (e.g. the line nodes next to a body), or () (unknown): the
      border's rows then come from the band's JVPs, coloured so that these rows'
      blocks stay apart, instead of from transposed JVPs.
    - `border_columns`: with a `border`, the entries of its rows (flat indices
      into its `border * b` entries) that the vector field reads and changes, or
      () (all): the others (e.g. unused components of a row) take no JVP.
    - `dense`: the Jacobian has no narrow band (every node couples to every other,
      e.g. through tensions solved over the whole chain): the solvers take the
      dense path without probing.
    - `sequential_elimination`: the band's blocks are eliminated
      from the first to the last (block Thomas, one step in a loop) instead of by
      cyclic reduction (log2 N unrolled levels): a smaller program, for models
      whose factorisations are a small share of a step (measured for mooring
      lines: docs/numerics.md, "Banded linear algebra").
    """

    bandwidth: int | None = None
    second_order: int = 0
    stage_jacobians: bool = False
    step_jacobians: bool = False
    jacobian: bool = False
    border: int = 0
    border_coupled: tuple[int, ...] = ()
    border_columns: tuple[int, ...] = ()
    dense: bool = False
    sequential_elimination: bool = False


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

    Optional: `structure(effects)`, what the implicit solvers may assume (a
    `SolverStructure`), and `vf_jacobian`, an analytic Jacobian; `preset_system`,
    the row of the accuracy presets (`jaxstring.preset`) the model uses.
    """

    accepts: ClassVar[tuple[type, ...]] = ()
    preset_system: ClassVar[str] = "other"

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

    def structure(self, effects) -> SolverStructure:
        """What the implicit solvers may assume of `vector_field` under `effects`
        (band, second-order layout, where Jacobians are taken, an analytic
        Jacobian): a `SolverStructure`. Default: nothing (detected or generic)."""
        del effects
        return SolverStructure()

    def vf_jacobian(self, t, y, effects, env):
        """The exact Jacobian of `vector_field` at `(t, y)` under `effects`, as a
        `jaxstring._linalg` block-tridiagonal matrix, for a model whose
        `structure(effects).jacobian` is True; else None (the solvers build it
        from coloured JVPs)."""
        del t, y, effects, env
        return None
