"""The string pendulum: a viscoelastic string with an end mass (Poth et al.), in
displacement variables and in natural variables (strain with tangent or angle).

Models in `models`, the tension laws (Kelvin-Voigt, the slack law) in `effects`,
the paper's scene in `scenes`, figures in `plot` (imported on demand: matplotlib).
Gravity is the chain core's (`jaxstring.chain.Gravity`), re-exported here.
"""

from ..chain import Gravity as Gravity
from .effects import (
    AbstractStringLoad as AbstractStringLoad,
    AbstractTensionLaw as AbstractTensionLaw,
    KelvinVoigt as KelvinVoigt,
    Kinematics as Kinematics,
    Loads as Loads,
    Slack as Slack,
)
from .models import (
    FORMULATIONS as FORMULATIONS,
    AbstractString as AbstractString,
    DisplacementString as DisplacementString,
    NaturalAngleString as NaturalAngleString,
    NaturalTangentString as NaturalTangentString,
)
from .scenes import string_pendulum as string_pendulum


__all__ = [
    "AbstractStringLoad",
    "AbstractTensionLaw",
    "Gravity",
    "KelvinVoigt",
    "Kinematics",
    "Loads",
    "Slack",
    "FORMULATIONS",
    "AbstractString",
    "DisplacementString",
    "NaturalAngleString",
    "NaturalTangentString",
    "string_pendulum",
]
