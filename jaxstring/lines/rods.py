"""Rods: rigid cylinders that lines attach to (MoorDyn v2's Rod).

A rod runs from end A to end B (length L = |B - A|, N segments, N + 1 nodes
evenly spaced along its axis q = (B - A)/L). It is rigid: no bending, no axial
strain. How it is held (`kind`):

- `"fixed"`: fixed in space (or, with `body`, fixed to a body);
- `"pinned"`: end A fixed (or on a body), free to rotate about it;
- `"free"`: six degrees of freedom;
- `"coupled"`, `"coupled_pinned"`: moved by a prescribed motion (all six degrees
  of freedom, or end A only).

A line end on a rod end is clamped to the rod's axis where the line has bending
stiffness (`jaxstring.lines.bending`): a fixed rod is the clamp of a cantilever.
"""

from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._arrays import param as _param
from .._validate import check_choice, check_finite, check_nonnegative, check_shape


class RodEnd(NamedTuple):
    """A line end on a rod end: `rod` (index in `LineNetwork.rods`), `end` ("A" or
    "B")."""

    rod: int
    end: str


ROD_KINDS = ("fixed", "pinned", "free", "coupled", "coupled_pinned")


class Rod(eqx.Module):
    """A rigid cylinder (see the module docstring).

    **Arguments:**

    - `end_a`, `end_b`: the ends, `(3,)`, m: in the earth frame, or in the body's
      frame (relative to its reference point) when `body` is given.
    - `segments`: N >= 0 (structure; 0 is a zero-length joint).
    - `d` (diameter, m), `w` (mass per length, kg/m), `Cd` (transverse drag on
      d l), `Ca` (transverse added mass on the displaced volume), `CdEnd` (axial
      drag on each submerged end's area pi d^2/4), `CaEnd` (axial added mass on
      each submerged end's half sphere pi d^3/12): scalars >= 0.
    - `kind`: one of "fixed", "pinned", "free", "coupled", "coupled_pinned"
      (structure).
    - `body`: index of the body it is fixed or pinned to (structure; None: the
      earth).
    """

    end_a: Float[Array, "3"] = _param()
    end_b: Float[Array, "3"] = _param()
    segments: int = eqx.field(static=True)
    d: Float[Array, ""] = _param()
    w: Float[Array, ""] = _param()
    Cd: Float[Array, ""] = _param(default=0.0)
    Ca: Float[Array, ""] = _param(default=0.0)
    CdEnd: Float[Array, ""] = _param(default=0.0)
    CaEnd: Float[Array, ""] = _param(default=0.0)
    kind: str = eqx.field(static=True, default="fixed")
    body: int | None = eqx.field(static=True, default=None)

    kinds: ClassVar[tuple[str, ...]] = ROD_KINDS

    def __check_init__(self):
        for name in ("end_a", "end_b"):
            check_shape(name, getattr(self, name), (3,), "m")
            check_finite(name, getattr(self, name))
        if (
            isinstance(self.segments, bool)
            or not isinstance(self.segments, int)
            or self.segments < 0
        ):
            raise ValueError(
                f"`segments` must be an integer >= 0; got {self.segments!r}."
            )
        for name, unit in (("d", "m"), ("w", "kg/m")):
            check_shape(name, getattr(self, name), (), unit)
            check_nonnegative(name, getattr(self, name), unit)
        for name in ("Cd", "Ca", "CdEnd", "CaEnd"):
            check_shape(name, getattr(self, name), ())
            check_nonnegative(name, getattr(self, name))
        check_choice("kind", self.kind, ROD_KINDS)
        if self.body is not None and self.kind not in ("fixed", "pinned"):
            raise ValueError(
                f"`kind` must be 'fixed' or 'pinned' for a rod on a body; got "
                f"{self.kind!r}."
            )

    @property
    def length(self):
        """Length |B - A|, m (0 for a zero-length rod)."""
        if self.segments == 0:
            return jnp.zeros(())
        return jnp.linalg.norm(self.end_b - self.end_a)

    def axis(self):
        """Unit axis from A to B (for a zero-length rod, end B is the direction)."""
        v = self.end_b if self.segments == 0 else self.end_b - self.end_a
        return v / jnp.linalg.norm(v)
