"""Mooring-line networks (MoorDyn's lumped-mass model): lines of lumped masses
between fixed, prescribed and free points, with bending stiffness and rods;
weight, buoyancy and Morison drag in a current (the chain loads of
`jaxstring.chain`), added mass, seabed contact with smooth friction;
time-varying unstretched lengths; MoorDyn v2 decks in and MoorDyn-style output
channels out.

Model and points in `models`, bending stiffness in `bending`, rods in `rods`,
rigid frames, prescribed motions and their equations of motion in `rigid`, seabed
contact in `effects`, decks and outputs in `moordyn`.
"""

from ..chain import (
    Buoyancy as Buoyancy,
    Drag as Drag,
    Gravity as Gravity,
    MotionEnd as MotionEnd,
)
from .bodies import (
    BODY_KINDS as BODY_KINDS,
    Body as Body,
    euler_angles as euler_angles,
    matrix_to_quat as matrix_to_quat,
    quat_multiply as quat_multiply,
    quat_to_matrix as quat_to_matrix,
    rotation_from_vector as rotation_from_vector,
    rotation_matrix as rotation_matrix,
    skew as skew,
)
from .effects import Seabed as Seabed
from .models import (
    BodyPoint as BodyPoint,
    FreePoint as FreePoint,
    LineNetwork as LineNetwork,
    equilibrium as equilibrium,
    initial_shape as initial_shape,
)
from .moordyn import (
    MoorDynDeck as MoorDynDeck,
    case_path as case_path,
    deck_scene as deck_scene,
    output_channels as output_channels,
    parse_moordyn as parse_moordyn,
    ramp_in as ramp_in,
    read_moordyn as read_moordyn,
    read_motion as read_motion,
    static_tensions as static_tensions,
    write_outputs as write_outputs,
)
from .rigid import RigidMotion as RigidMotion
from .rods import Rod as Rod, RodEnd as RodEnd
from .statics import (
    MooringEquilibrium as MooringEquilibrium,
    MooringLoads as MooringLoads,
    MooringPoint as MooringPoint,
    MooringSystem as MooringSystem,
    coupled_stiffness as coupled_stiffness,
    mooring_equilibrium as mooring_equilibrium,
    mooring_system as mooring_system,
)


__all__ = [
    "Buoyancy",
    "Drag",
    "Gravity",
    "MotionEnd",
    "Seabed",
    "BodyPoint",
    "FreePoint",
    "LineNetwork",
    "RigidMotion",
    "Rod",
    "RodEnd",
    "equilibrium",
    "initial_shape",
    "MoorDynDeck",
    "case_path",
    "deck_scene",
    "output_channels",
    "parse_moordyn",
    "ramp_in",
    "read_motion",
    "read_moordyn",
    "static_tensions",
    "write_outputs",
    "BODY_KINDS",
    "Body",
    "euler_angles",
    "matrix_to_quat",
    "quat_multiply",
    "quat_to_matrix",
    "rotation_from_vector",
    "rotation_matrix",
    "skew",
    "MooringEquilibrium",
    "MooringLoads",
    "MooringPoint",
    "MooringSystem",
    "coupled_stiffness",
    "mooring_equilibrium",
    "mooring_system",
]
