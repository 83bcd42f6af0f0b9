"""diffrax adjoints by name (`SolveConfig.adjoint`)."""

import diffrax as dfx

from ._solvers.names import ADJOINTS
from ._validate import check_choice


class SensitivityAdjoint(dfx.ForwardMode):
    """Marker adjoint: derivatives from forward sensitivities integrated with the
    state under the same error control (`jaxstring._sensitivity`). A plain solve
    under it is a forward-mode solve."""


def make_adjoint(adjoint, checkpoints=None):
    """A diffrax adjoint from a name of `ADJOINTS` (`"auto"` and `"recursive"`:
    diffrax's checkpointed reverse mode; `"sensitivity"`: `SensitivityAdjoint`) or
    a `diffrax.AbstractAdjoint` instance (returned as is)."""
    if isinstance(adjoint, dfx.AbstractAdjoint):
        return adjoint
    check_choice("adjoint", adjoint, ADJOINTS)
    if adjoint in ("auto", "recursive"):
        return dfx.RecursiveCheckpointAdjoint(checkpoints=checkpoints)
    if adjoint == "direct":
        return dfx.DirectAdjoint()
    if adjoint == "backsolve":
        return dfx.BacksolveAdjoint()
    if adjoint == "sensitivity":
        return SensitivityAdjoint()
    return dfx.ForwardMode()
