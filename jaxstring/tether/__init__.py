"""The inextensible underwater tether (Blintsov): a chain of lumped masses whose
constraint tensions come from the ACEAM regulator, an exact tridiagonal solve, or
stiff LMS springs; weight, buoyancy and Morison drag in a current; pay-out and
haul-in from a winch.

Models and ends in `models`, effects in `effects`, the paper's scenes in `scenes`,
figures in `plot` (imported on demand: matplotlib).
"""

from .effects import (
    AbstractTetherLoad as AbstractTetherLoad,
    Buoyancy as Buoyancy,
    Drag as Drag,
    TetherKinematics as TetherKinematics,
    Weight as Weight,
)
from .models import (
    AbstractEnd as AbstractEnd,
    AbstractTether as AbstractTether,
    AceamTether as AceamTether,
    CoupledEnd as CoupledEnd,
    EndKinematics as EndKinematics,
    ExactTether as ExactTether,
    FixedEnd as FixedEnd,
    FreeEnd as FreeEnd,
    LmsTether as LmsTether,
    PiecewiseLinear as PiecewiseLinear,
    PrescribedEnd as PrescribedEnd,
    arc_state as arc_state,
    hanging_state as hanging_state,
)
from .scenes import (
    RHO_TABLE1 as RHO_TABLE1,
    tether_fixed as tether_fixed,
    tether_fold as tether_fold,
    tether_winch as tether_winch,
)


__all__ = [
    "AbstractTetherLoad",
    "Buoyancy",
    "Drag",
    "TetherKinematics",
    "Weight",
    "AbstractEnd",
    "AbstractTether",
    "AceamTether",
    "CoupledEnd",
    "EndKinematics",
    "ExactTether",
    "FixedEnd",
    "FreeEnd",
    "LmsTether",
    "PiecewiseLinear",
    "PrescribedEnd",
    "arc_state",
    "hanging_state",
    "tether_fixed",
    "tether_fold",
    "tether_winch",
]
