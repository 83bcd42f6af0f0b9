"""MoorDyn v2 input decks in, MoorDyn-style output channels out.

`parse_moordyn(path)` reads the LINE TYPES (or LINE DICTIONARY), ROD TYPES,
BODIES, RODS, POINTS (or POINT / CONNECTION / NODE PROPERTIES), LINES (or LINE
PROPERTIES), OPTIONS and OUTPUTS sections of a MoorDyn v2 deck into a
`MoorDynDeck`, every column and attachment keyword as MoorDyn 2.7 reads them
(sections in any order; column headers are not read, only positions);
`read_moordyn(path, ...)` builds the `jaxstring.Scene` at static equilibrium
(jaxstring's own solve: catenary start and pseudo-transient Newton, not MoorDyn's
`.ic` snapshot). Anything malformed or that the model does not have -- wave
kinematics, bending-moment and non-linear stiffness tables, vortex-induced lift on
lines with interior nodes, failure criteria, unknown options or attachment
keywords -- raises a ValueError naming the file, the line, the column and the
valid range; nothing is skipped silently.

Conventions (MoorDyn's): z up with the still-water surface at z = 0; the seabed at
z = -WtrDpth; g = 9.80665 m/s^2, water density 1025 kg/m^3, kBot = 3e6 Pa/m,
cBot = 3e5 Pa s/m, FrictionCoefficient = 0 unless the deck says otherwise; a
negative BA is minus the damping ratio; a negative UnstrLen scales the distance
between the line's ends. End B of a line is its fairlead end (MoorDyn's FAIRTEN
channel), end A its anchor end (ANCHTEN).
"""

import collections
import dataclasses
import math
import os
import re

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._arrays import f64
from .._environment import Environment
from .._programs import eager_jit
from .._scene import Scene
from .._validate import options_of, same_signature
from ..chain import Buoyancy, Drag, FixedEnd, Gravity, PrescribedEnd
from .bodies import Body, rotation_matrix
from .effects import Seabed
from .models import (
    BodyPoint,
    FreePoint,
    LineNetwork,
    equilibrium,
    rest_end_tensions,
)
from .rigid import RigidMotion
from .rods import Rod, RodEnd


MOORDYN_G = 9.80665

# MoorDyn's validation decks and reference series (v2.7.1, BSD 3-Clause: see
# cases/LICENSE.txt and cases/README.md).
CASES_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "cases")


def case_path(name: str) -> str:
    """Path of one of MoorDyn's validation files shipped with jaxstring:
    `"pendulum.txt"`, `"lifting.txt"`, `"WD0050_Chain.txt"`,
    `"WD0200_Chain.txt"`, `"lines.txt"`, `"QuasiStatic/ZZP1_A1.txt"`,
    `"QuasiStatic/WD0050_Chain_ZZP1_A1.txt"`,
    `"QuasiStatic/WD0200_Chain_ZZP1_A1.txt"`; and jaxstring's own example deck
    `"turret_fpso.txt"` (a turret-moored FPSO's nine chain/wire/chain legs)."""
    path = os.path.join(CASES_DIR, name)
    if not os.path.isfile(path):
        known = sorted(
            os.path.relpath(os.path.join(d, f), CASES_DIR)
            for d, _, fs in os.walk(CASES_DIR)
            for f in fs
            if f.endswith((".txt", ".dat")) and f not in ("LICENSE.txt", "README.md")
        )
        raise ValueError(f"unknown case {name!r}; valid: {', '.join(known)}.")
    return path


_TYPE_COLUMNS = ("Name", "Diam", "Mass/m", "EA", "BA/-zeta", "EI", "Cd", "Ca", "CdAx",
                 "CaAx")  # fmt: skip
_TYPE_EXTRA = ("Cl", "dF", "cF")
_ROD_TYPE_COLUMNS = ("Name", "Diam", "Mass/m", "Cd", "Ca", "CdEnd", "CaEnd")
_BODY_COLUMNS = ("ID", "Attachment", "X0", "Y0", "Z0", "r0", "p0", "y0", "Mass", "CG",
                 "I", "Volume", "CdA", "Ca")  # fmt: skip
_ROD_COLUMNS = ("ID", "RodType", "Attachment", "Xa", "Ya", "Za", "Xb", "Yb", "Zb",
                "NumSegs")  # fmt: skip
_POINT_COLUMNS = ("ID", "Type", "X", "Y", "Z", "Mass", "Volume", "CdA", "Ca")
_LINE_COLUMNS = ("ID", "LineType", "AttachA", "AttachB", "UnstrLen", "NumSegs")

_SECTIONS = {
    "LINE TYPES": "types",
    "LINE DICTIONARY": "types",
    "ROD TYPES": "rod_types",
    "ROD DICTIONARY": "rod_types",
    "BODIES": "bodies",
    "BODY LIST": "bodies",
    "BODY PROPERTIES": "bodies",
    "RODS": "rods",
    "ROD LIST": "rods",
    "ROD PROPERTIES": "rods",
    "POINTS": "points",
    "POINT PROPERTIES": "points",
    "POINT LIST": "points",
    "CONNECTION PROPERTIES": "points",
    "NODE PROPERTIES": "points",
    "LINES": "lines",
    "LINE PROPERTIES": "lines",
    "LINE LIST": "lines",
    "OPTIONS": "options",
    "SOLVER OPTIONS": "options",
    "OUTPUTS": "outputs",
}
_TABLES = ("types", "rod_types", "bodies", "rods", "points", "lines")
_UNSUPPORTED_SECTIONS = ("FAILURE", "EXTERNAL LOADS", "MOTIONS")
_POINT_KINDS = {
    "fixed": "fixed",
    "fix": "fixed",
    "anchor": "fixed",
    "vessel": "coupled",
    "ves": "coupled",
    "coupled": "coupled",
    "cpld": "coupled",
    "fairlead": "coupled",
    "free": "free",
    "connect": "free",
    "con": "free",
    "point": "free",
}
# Attachment keywords (MoorDyn2.cpp), upper case.
_BODY_KINDS = {
    "FIXED": "fixed",
    "FIX": "fixed",
    "ANCHOR": "fixed",
    "FREE": "free",
    "VESSEL": "coupled",
    "VES": "coupled",
    "COUPLED": "coupled",
    "CPLD": "coupled",
    "VESSELPINNED": "coupled_pinned",
    "VESPIN": "coupled_pinned",
    "CPLDPIN": "coupled_pinned",
    "COUPLEDPINNED": "coupled_pinned",
}
# A rod takes a body's kinds and can also be pinned or free like a point.
_ROD_KINDS = _BODY_KINDS | {
    "PINNED": "pinned",
    "PIN": "pinned",
    "POINT": "free",
    "CON": "free",
}

# Options read into the scene: deck name (lower case) -> key.
_PHYSICS_OPTIONS = {
    "g": "g",
    "gravity": "g",
    "wtrdnsty": "rho",
    "rho": "rho",
    "rho_w": "rho",
    "wtrdpth": "depth",
    "depth": "depth",
    "kbot": "kBot",
    "kb": "kBot",
    "cbot": "cBot",
    "cb": "cBot",
    "frictioncoefficient": "friction",
    "fricdamp": "fric_damp",
    "statdynfricscale": "stat_dyn_fric_scale",
}
# Options of MoorDyn's own numerics and files: read and reported, not needed.
_NUMERIC_OPTIONS = {
    "writelog", "dtm", "dt", "cfl", "tscheme", "dtic", "tmaxic", "cdscaleic",
    "threshic", "icgendynamic", "genDynamicIC".lower(), "fileic", "disableouttime",
    "dtout", "writeunits", "dtwave", "icdfac", "icthresh", "ictmax", "fricdamp_ic",
    "disableoutput",
}  # fmt: skip
# Options whose non-zero value asks for something the model does not have.
_ZERO_ONLY_OPTIONS = {"waterkin", "wavekin", "currents", "waves", "seafloor",
                      "inertialf", "inertialf_rampt", "viv"}  # fmt: skip


@dataclasses.dataclass
class MoorDynDeck:
    """A parsed MoorDyn v2 deck.

    **Fields:** `path`; `types` (line type name -> dict of d, w, EA, BA, EI, Cd,
    Ca, CdAx, CaAx, Cl); `points` (list of dicts: id, kind 'fixed' | 'coupled' |
    'free' | 'body', body (the body's ID for kind 'body', else None), position (on
    a body: in its frame, relative to its reference point), mass, volume, CdA,
    Ca); `lines` (list of dicts: id, type, a, b, L, segments; an end is a point ID
    (int) or a rod end `(rod ID, "A" | "B")`); `rod_types` (name -> dict of d, w,
    Cd, Ca, CdEnd, CaEnd); `bodies` (list of dicts: id, kind 'fixed' | 'free' |
    'coupled' | 'coupled_pinned', position (m), angles (rad, MoorDyn's Euler
    angles: R = Rx(roll) Ry(pitch) Rz(yaw)), mass, cg (3,), inertia (3,) about
    the CG in the body's axes, volume, CdA (6,), Ca (3,)); `rods` (list of dicts:
    id, type, kind 'fixed' | 'pinned' | 'free' | 'coupled' | 'coupled_pinned',
    body (ID or None), end_a, end_b (m; in the body's frame on a body), segments,
    outputs); `options` (the physics values after MoorDyn's defaults: g, rho,
    depth, kBot, cBot, friction, fric_damp, stat_dyn_fric_scale); `numerics` (the
    deck's own numerical options, e.g. dtM, cfl, tScheme, as text); `outputs`
    (the OUTPUTS section's channel names).
    """

    path: str
    types: dict
    points: list
    lines: list
    options: dict
    numerics: dict
    outputs: list
    rod_types: dict = dataclasses.field(default_factory=dict)
    bodies: list = dataclasses.field(default_factory=list)
    rods: list = dataclasses.field(default_factory=list)


class _Where:
    def __init__(self, path, lineno, text):
        self.path, self.lineno, self.text = path, lineno, text

    def error(self, field_index, fields, message):
        col = 1
        if fields and 0 <= field_index < len(fields):
            pos = 0
            for i, f in enumerate(fields):
                pos = self.text.index(f, pos)
                if i == field_index:
                    break
                pos += len(f)
            col = pos + 1
        return ValueError(
            f"{self.path}: line {self.lineno}, column {col}: {message} "
            f"(line text: {self.text.strip()!r})"
        )


def _parse_float(text):
    return float(text.replace("D", "E").replace("d", "e"))


def _number(where, fields, i, name, positive=False, nonnegative=False, text=None):
    if i >= len(fields):
        raise where.error(len(fields) - 1, fields, f"missing column {i + 1} ({name})")
    text = fields[i] if text is None else text
    try:
        v = _parse_float(text)
    except ValueError:
        raise where.error(
            i, fields, f"column {i + 1} ({name}) must be a number; got {text!r}"
        ) from None
    if not math.isfinite(v):
        raise where.error(i, fields, f"column {i + 1} ({name}) must be finite")
    if positive and v <= 0:
        raise where.error(i, fields, f"column {i + 1} ({name}) must be > 0; got {v:g}")
    if nonnegative and v < 0:
        raise where.error(i, fields, f"column {i + 1} ({name}) must be >= 0; got {v:g}")
    return v


def _numbers(where, fields, i, name, counts, nonnegative=False):
    """Column i as 1 or more '|'-separated numbers, their count one of `counts`."""
    if i >= len(fields):
        raise where.error(len(fields) - 1, fields, f"missing column {i + 1} ({name})")
    parts = fields[i].split("|")
    if len(parts) not in counts:
        valid = " or ".join(str(c) for c in counts)
        raise where.error(
            i,
            fields,
            f"column {i + 1} ({name}) must hold {valid} '|'-separated numbers; got "
            f"{fields[i]!r}",
        )
    return [_number(where, fields, i, name, nonnegative=nonnegative, text=p)
            for p in parts]  # fmt: skip


def _integer(where, fields, i, name, minimum):
    v = _number(where, fields, i, name)
    if v != int(v) or v < minimum:
        raise where.error(
            i, fields, f"column {i + 1} ({name}) must be an integer >= {minimum}"
        )
    return int(v)


def _decompose(text):
    """MoorDyn's decomposeString: alternating letter and digit runs, upper case:
    'Body1Pinned' -> ['BODY', '1', 'PINNED'], or None if it has other characters."""
    parts = re.findall(r"[A-Za-z]+|\d+", text)
    if "".join(parts) != text:
        return None
    return [p.upper() for p in parts]


def _section_of(text):
    """The section a dashed header line opens: a key of _SECTIONS, an unsupported
    name, 'end', or None (a plain line)."""
    if "---" not in text:
        return None
    title = text.strip("-= \t\r\n").upper()
    title = " ".join(title.replace("-", " ").split())
    if "NEED THIS LINE" in title or title.startswith("END"):
        return "end"
    for name in _UNSUPPORTED_SECTIONS:
        if title.startswith(name) or title == name:
            return ("unsupported", name)
    # longest match first ("LINE TYPES" before "LINES")
    for name in sorted(_SECTIONS, key=len, reverse=True):
        if title.startswith(name):
            return name
    return ("unknown", title)


def parse_moordyn(path) -> MoorDynDeck:
    """Parse a MoorDyn v2 input deck (see the module docstring).

    Raises ValueError naming the file, line and column of anything malformed or
    unsupported."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"`path`: no MoorDyn deck at {path!r}.")
    with open(path, encoding="utf-8", errors="replace") as f:
        text = f.read().splitlines()
    rows = {k: [] for k in _TABLES}
    outputs = []
    raw_options, numerics = {}, {}
    section, skip = None, 0
    seen = set()
    for lineno, line in enumerate(text, start=1):
        where = _Where(path, lineno, line)
        kind = _section_of(line)
        if kind is not None:
            if kind == "end":
                section = "end"
                break
            if isinstance(kind, tuple) and kind[0] == "unknown" and section is None:
                continue  # the deck's title line
            if isinstance(kind, tuple):
                what = "is not supported" if kind[0] == "unsupported" else "is unknown"
                raise where.error(
                    0,
                    line.split(),
                    f"section {kind[1]!r} {what} (jaxstring reads LINE TYPES, ROD "
                    "TYPES, BODIES, RODS, POINTS, LINES, OPTIONS and OUTPUTS; failure "
                    "criteria, external loads and wave kinematics are not modelled)",
                )
            section = _SECTIONS[kind]
            if section in seen and section != "outputs":
                raise where.error(0, line.split(), f"section {kind!r} appears twice")
            seen.add(section)
            skip = 2 if section in _TABLES else 0
            continue
        if section is None or not line.strip():
            continue
        if skip:
            skip -= 1
            continue
        fields = line.split()
        if section in _TABLES:
            rows[section].append((where, fields))
        elif section == "options":
            _option_row(where, fields, raw_options, numerics)
        elif section == "outputs":
            if line.strip().upper() != "END":
                outputs.extend(fields)
    where_end = _Where(path, len(text), text[-1] if text else "")
    # MoorDyn's order: line types, rod types, bodies, rods, points, lines.
    types, rod_types = {}, {}
    for w, f in rows["types"]:
        _type_row(w, f, types)
    for w, f in rows["rod_types"]:
        _rod_type_row(w, f, rod_types)
    bodies = [_body_row(w, f, k + 1) for k, (w, f) in enumerate(rows["bodies"])]
    rods = [_rod_row(w, f, k + 1, rod_types, bodies)
            for k, (w, f) in enumerate(rows["rods"])]  # fmt: skip
    points = []
    for w, f in rows["points"]:
        _point_row(w, f, points, bodies)
    ids = {p["id"]: p for p in points}
    parsed = [_line_row(w, f, types, ids, rods, bodies) for w, f in rows["lines"]]
    if not (parsed or rods or bodies):
        raise where_end.error(
            0, [], "the deck has no line, rod or body (LINES, RODS, BODIES sections)"
        )
    _check_free_bodies(rows["bodies"], bodies, points, rods, parsed)
    options = {
        "g": MOORDYN_G,
        "rho": 1025.0,
        "depth": 0.0,
        "kBot": 3.0e6,
        "cBot": 3.0e5,
        "friction": 0.0,
        "fric_damp": 200.0,
        "stat_dyn_fric_scale": 1.0,
    }
    for key, (value, where, fields) in raw_options.items():
        options[key] = value
        if key == "stat_dyn_fric_scale" and value != 1.0:
            raise where.error(
                0, fields, "StatDynFricScale other than 1 is not supported"
            )
    return MoorDynDeck(path, types, points, parsed, options, numerics, outputs,
                       rod_types, bodies, rods)  # fmt: skip


def _type_row(where, fields, types):
    _need_columns(where, fields, _TYPE_COLUMNS, "a line type")
    if len(fields) not in (10, 11, 13):
        raise where.error(
            len(fields) - 1,
            fields,
            f"a line type has 10, 11 or 13 columns ({' '.join(_TYPE_COLUMNS)} "
            f"[Cl [dF cF]]); got {len(fields)}",
        )
    name = fields[0]
    for i in (3, 4):
        if "|" in fields[i] or not _is_number(fields[i]):
            raise where.error(
                i,
                fields,
                f"column {i + 1} ({_TYPE_COLUMNS[i]}) must be one number: non-linear "
                "stiffness or damping tables are not supported",
            )
    t = {
        "d": _number(where, fields, 1, "Diam", positive=True),
        "w": _number(where, fields, 2, "Mass/m", positive=True),
        "EA": _number(where, fields, 3, "EA", positive=True),
        "BA": _number(where, fields, 4, "BA/-zeta"),
    }
    if not _is_number(fields[5]):
        raise where.error(
            5,
            fields,
            f"column 6 (EI) must be a number >= 0 (N m^2); got {fields[5]!r} "
            "(bending-moment curves from files are not supported)",
        )
    t["EI"] = _number(where, fields, 5, "EI", nonnegative=True)
    for i, key in zip(range(6, 10), ("Cd", "Ca", "CdAx", "CaAx")):
        t[key] = _number(where, fields, i, key, nonnegative=True)
    t["Cl"] = 0.0
    if len(fields) > 10:
        t["Cl"] = _number(where, fields, 10, "Cl", nonnegative=True)
        t["Cl_where"] = (where, fields)
    for i in (11, 12):
        if i < len(fields):
            _number(where, fields, i, _TYPE_EXTRA[i - 10])
    if name in types:
        raise where.error(0, fields, f"line type {name!r} is defined twice")
    types[name] = t


def _rod_type_row(where, fields, rod_types):
    _need_columns(where, fields, _ROD_TYPE_COLUMNS, "a rod type")
    name = fields[0]
    if name in rod_types:
        raise where.error(0, fields, f"rod type {name!r} is defined twice")
    t = {
        "d": _number(where, fields, 1, "Diam", positive=True),
        "w": _number(where, fields, 2, "Mass/m", nonnegative=True),
    }
    for i, key in zip(range(3, 7), ("Cd", "Ca", "CdEnd", "CaEnd")):
        t[key] = _number(where, fields, i, key, nonnegative=True)
    rod_types[name] = t


def _sequential_id(where, fields, expected, what):
    got = _integer(where, fields, 0, "ID", 1)
    if got != expected:
        raise where.error(
            0, fields, f"{what} IDs must run 1, 2, 3, ... in order; expected {expected}"
        )
    return got


def _body_row(where, fields, expected):
    _need_columns(where, fields, _BODY_COLUMNS, "a body")
    bid = _sequential_id(where, fields, expected, "body")
    key = fields[1].upper()
    kind = _BODY_KINDS.get(key)
    if kind is None:
        raise where.error(
            1,
            fields,
            f"column 2 (Attachment) {fields[1]!r} is not a body attachment; valid: "
            "Free, Fixed/Anchor, Coupled/Vessel, CoupledPinned/VesselPinned",
        )
    pos = [_number(where, fields, i, n) for i, n in zip((2, 3, 4), "XYZ")]
    angles = [
        math.radians(_number(where, fields, i, n))
        for i, n in zip((5, 6, 7), ("r0", "p0", "y0"))
    ]
    mass = _number(where, fields, 8, "Mass", nonnegative=True)
    cg = _numbers(where, fields, 9, "CG", (1, 3))
    cg = [0.0, 0.0, cg[0]] if len(cg) == 1 else cg
    inertia = _numbers(where, fields, 10, "I", (1, 3), nonnegative=True)
    inertia = inertia * 3 if len(inertia) == 1 else inertia
    volume = _number(where, fields, 11, "Volume", nonnegative=True)
    c = _numbers(where, fields, 12, "CdA", (1, 2, 3, 6), nonnegative=True)
    CdA = {1: lambda: c * 6, 2: lambda: [c[0]] * 3 + [c[1]] * 3,
           3: lambda: c + c, 6: lambda: c}[len(c)]()  # fmt: skip
    Ca = _numbers(where, fields, 13, "Ca", (1, 3), nonnegative=True)
    Ca = Ca * 3 if len(Ca) == 1 else Ca
    return {"id": bid, "kind": kind, "position": pos, "angles": angles,
            "mass": mass, "cg": cg, "inertia": inertia, "volume": volume,
            "CdA": CdA, "Ca": Ca, "line": where.lineno}  # fmt: skip


def _body_ref(where, fields, i, parts, bodies, what):
    """The body ID of an attachment 'BODYn...' (checked against BODIES)."""
    if len(parts) < 2 or not parts[1].isdigit():
        raise where.error(
            i, fields, f"column {i + 1} ({what}) {fields[i]!r}: 'Body' needs a number"
        )
    n = int(parts[1])
    _check_id(where, fields, i, what, n, "body", "BODIES", len(bodies))
    return n


def _check_id(where, fields, i, what, n, kind, section, count):
    """Refuse the `kind` ID `n` named in column `i` (`what`) unless it is one of
    the `count` in `section` (1..count)."""
    if not 1 <= n <= count:
        raise where.error(
            i,
            fields,
            f"column {i + 1} ({what}) {fields[i]!r}: {kind} {n} is not in {section} "
            f"(valid: 1..{count})",
        )


def _rod_row(where, fields, expected, rod_types, bodies):
    _need_columns(where, fields, _ROD_COLUMNS, "a rod", " [RodOutputs]")
    rid = _sequential_id(where, fields, expected, "rod")
    if fields[1] not in rod_types:
        raise where.error(
            1, fields, f"rod type {fields[1]!r} is not in ROD TYPES ({list(rod_types)})"
        )
    parts = _decompose(fields[2]) or []
    body = None
    if parts and parts[0] == "BODY":
        body = _body_ref(where, fields, 2, parts, bodies, "Attachment")
        rest = parts[2:]
        if rest in ([], ["PINNED"], ["PIN"]):
            kind = "fixed" if not rest else "pinned"
        else:
            kind = None
    else:
        kind = _ROD_KINDS.get(parts[0]) if len(parts) == 1 else None
    if kind is None:
        raise where.error(
            2,
            fields,
            f"column 3 (Attachment) {fields[2]!r} is not a rod attachment; valid: "
            "Fixed/Anchor, Pinned, Free/Point, Coupled/Vessel, CoupledPinned/"
            "VesselPinned, Body<n>, Body<n>Pinned",
        )
    a = [_number(where, fields, i, n) for i, n in zip((3, 4, 5), ("Xa", "Ya", "Za"))]
    b = [_number(where, fields, i, n) for i, n in zip((6, 7, 8), ("Xb", "Yb", "Zb"))]
    N = _integer(where, fields, 9, "NumSegs", 0)
    length = math.dist(a, b)
    if N > 0 and length == 0:
        raise where.error(
            6, fields, "a rod with NumSegs > 0 needs end B away from end A"
        )
    if N == 0 and math.hypot(*b) == 0:
        raise where.error(
            6, fields, "a zero-length rod (NumSegs 0) needs a direction in Xb Yb Zb"
        )
    return {"id": rid, "type": fields[1], "kind": kind, "body": body,
            "end_a": a, "end_b": b, "segments": N,
            "outputs": fields[10] if len(fields) > 10 else "-",
            "line": where.lineno}  # fmt: skip


def _check_free_bodies(rows, bodies, points, rods, lines):
    """A free body must have inertia: its own mass or volume, or points, rods or
    lines on it that carry mass."""
    for (where, fields), b in zip(rows, bodies):
        if b["kind"] not in ("free",) or b["mass"] > 0 or b["volume"] > 0:
            continue
        on = [p for p in points if p["body"] == b["id"]]
        carried = any(p["mass"] > 0 or p["volume"] > 0 for p in on)
        carried |= any(r["body"] == b["id"] for r in rods)
        ids = {p["id"] for p in on}
        carried |= any(ln["a"] in ids or ln["b"] in ids for ln in lines)
        if not carried:
            raise where.error(
                8,
                fields,
                "a Free body with zero Mass and zero Volume has no inertia: give "
                "Mass > 0 (kg) or Volume > 0 (m^3), or attach points, rods or lines "
                "with mass to it",
            )


def _is_number(text):
    try:
        _parse_float(text)
        return True
    except ValueError:
        return False


def _need_columns(where, fields, columns, what, more=""):
    if len(fields) < len(columns):
        raise where.error(
            len(fields) - 1,
            fields,
            f"{what} needs {len(columns)} columns ({' '.join(columns)}{more}); "
            f"got {len(fields)}",
        )


def _point_row(where, fields, points, bodies):
    _need_columns(where, fields, _POINT_COLUMNS, "a point")
    pid = _integer(where, fields, 0, "ID", 0)
    parts = _decompose(fields[1]) or [""]
    body = None
    if parts[0] == "BODY":
        body = _body_ref(where, fields, 1, parts, bodies, "Type")
        if len(parts) > 2:
            raise where.error(
                1, fields, f"point type {fields[1]!r}: valid: Body<n> (no suffix)"
            )
        kind = "body"
    else:
        kind = _POINT_KINDS.get(fields[1].lower())
    if kind is None:
        raise where.error(
            1,
            fields,
            f"point type {fields[1]!r} is not valid (Fixed/Anchor, Vessel/Coupled/"
            "Fairlead, Free/Connect/Point, Body<n>)",
        )
    if any(p["id"] == pid for p in points):
        raise where.error(0, fields, f"point ID {pid} is defined twice")
    pos = [_number(where, fields, i, n) for i, n in zip((2, 3, 4), "XYZ")]
    cda, ca = 7, 8
    if len(fields) >= 12:  # ID Type X Y Z M V FX FY FZ CdA Ca
        for i, n in zip((7, 8, 9), ("FX", "FY", "FZ")):
            if _number(where, fields, i, n) != 0:
                raise where.error(
                    i, fields, f"column {i + 1} ({n}): constant point forces are "
                    "not supported (valid: 0)"
                )  # fmt: skip
        cda, ca = 10, 11
    points.append(
        {
            "id": pid,
            "kind": kind,
            "body": body,
            "position": pos,
            "mass": _number(where, fields, 5, "Mass", nonnegative=True),
            "volume": _number(where, fields, 6, "Volume", nonnegative=True),
            "CdA": _number(where, fields, cda, "CdA", nonnegative=True),
            "Ca": _number(where, fields, ca, "Ca", nonnegative=True),
        }
    )


def _line_end(where, fields, i, name, points, rods):
    """A line end: a point ID (int) or a rod end (rod ID, 'A' | 'B')."""
    text = fields[i]
    parts = _decompose(text) or []
    named = len(parts) == 2 and parts[0] in ("P", "POINT", "C", "CON")
    if text.isdigit() or (named and parts[1].isdigit()):
        pid = int(parts[-1])
        if pid not in points:
            raise where.error(i, fields, f"point {pid} is not in POINTS")
        return pid
    if len(parts) == 3 and parts[0] in ("R", "ROD") and parts[2] in ("A", "B"):
        rid = int(parts[1])
        _check_id(where, fields, i, name, rid, "rod", "RODS", len(rods))
        return (rid, parts[2])
    raise where.error(
        i,
        fields,
        f"column {i + 1} ({name}) {text!r} is not a line end; valid: a point ID "
        "(n, Pn, POINTn, Cn, CONn) or a rod end (RnA, RnB, RODnA, RODnB)",
    )


def end_position(deck: MoorDynDeck, end) -> np.ndarray:
    """Global position at the deck's initial pose of a line end (a point ID or a
    rod end `(rod ID, "A" | "B")`), m."""
    if isinstance(end, tuple):
        rod = deck.rods[end[0] - 1]
        local = np.asarray(rod["end_a"] if end[1] == "A" else rod["end_b"], float)
        if rod["segments"] == 0 and end[1] == "B":
            local = np.asarray(rod["end_a"], float)
        body = rod["body"]
    else:
        p = next(p for p in deck.points if p["id"] == end)
        local, body = np.asarray(p["position"], float), p["body"]
    if body is None:
        return local
    b = deck.bodies[body - 1]
    R = np.asarray(rotation_matrix(jnp.asarray(b["angles"])))
    return np.asarray(b["position"]) + R @ local


def _line_row(where, fields, types, points, rods, bodies):
    _need_columns(where, fields, _LINE_COLUMNS, "a line", " [LineOutputs]")
    lid = _integer(where, fields, 0, "ID", 0)
    if fields[1] not in types:
        raise where.error(
            1, fields, f"line type {fields[1]!r} is not in LINE TYPES ({list(types)})"
        )
    ends = [_line_end(where, fields, i, name, points, rods)
            for i, name in ((2, "AttachA"), (3, "AttachB"))]  # fmt: skip
    if ends[0] == ends[1]:
        raise where.error(3, fields, "a line cannot join a line end to itself")
    L = _number(where, fields, 4, "UnstrLen")
    if L == 0:
        raise where.error(4, fields, "column 5 (UnstrLen) must not be 0")
    if L < 0:  # MoorDyn: a factor on the distance between the ends
        deck = MoorDynDeck("", types, list(points.values()), [], {}, {}, [], {},
                           bodies, rods)  # fmt: skip
        pa, pb = (end_position(deck, e) for e in ends)
        L = -L * float(np.linalg.norm(pb - pa))
    N = _integer(where, fields, 5, "NumSegs", 1)
    Cl = types[fields[1]]["Cl"]
    if Cl != 0 and N > 1:
        w, f = types[fields[1]]["Cl_where"]
        raise w.error(
            10,
            f,
            f"column 11 (Cl = {Cl:g}): vortex-induced lift is not modelled; valid: 0 "
            f"for a line type of lines with more than one segment (line {lid} has "
            f"{N})",
        )
    return {"id": lid, "type": fields[1], "a": ends[0], "b": ends[1], "L": L,
            "segments": N}  # fmt: skip


def _option_row(where, fields, raw, numerics):
    if len(fields) < 2:
        raise where.error(0, fields, "an option needs a value and a name")
    value, name = fields[0], fields[1]
    key = name.lower()
    if key in _PHYSICS_OPTIONS:
        v = _number(where, fields, 0, name)
        target = _PHYSICS_OPTIONS[key]
        if target == "fric_damp" and v <= 0:
            raise where.error(0, fields, f"option {name} must be > 0; got {v:g}")
        if target in ("rho", "g", "kBot", "cBot", "friction", "depth") and v < 0:
            raise where.error(0, fields, f"option {name} must be >= 0; got {v:g}")
        raw[target] = (v, where, fields)
    elif key in _ZERO_ONLY_OPTIONS:
        if not _is_number(value) or float(value) != 0:
            raise where.error(
                0,
                fields,
                f"option {name} = {value} is not supported (wave kinematics, currents "
                "from files, seafloor files and VIV are not modelled)",
            )
        numerics[name] = value
    elif key in _NUMERIC_OPTIONS:
        numerics[name] = value
    else:
        raise where.error(1, fields, f"option {name!r} is unknown or not supported")


# ---------------------------------------------------------------------------
# Scene


def read_motion(path, n_coupled=None):
    """A motion table: whitespace-separated rows `t x y z [rx ry rz]` (s, m, rad):
    the offsets of the coupled objects from their deck poses (MoorDyn's Euler
    angles for the rotations). Returns `(times (K,), offsets (K, 3) or (K, 6))`."""
    del n_coupled
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"`motion`: no motion table at {path!r}.")
    try:
        data = np.loadtxt(path, ndmin=2)
    except ValueError as e:
        raise ValueError(f"`motion`: {path} is not a table of numbers: {e}") from None
    if data.shape[1] not in (4, 7):
        raise ValueError(
            f"`motion`: {path} has {data.shape[1]} columns; valid: 4 (t x y z) or 7 "
            "(t x y z rx ry rz)."
        )
    t = data[:, 0]
    if data.shape[0] < 2 or np.any(np.diff(t) <= 0):
        raise ValueError(f"`motion`: the times in {path} must increase strictly.")
    return t, data[:, 1:]


def ramp_in(times, offsets, duration):
    """A motion table's offsets ramped in over its first `duration` seconds:
    times sin^2(pi/2 (t - t0)/duration), so that a table that starts at full
    speed (such as ZZP1_A1 at t = -10 s) starts from rest with no step in the
    point's velocity. Returns the offsets `(K, 3)` or `(K, 6)`, m (and rad)."""
    times = np.asarray(times, float)
    offsets = np.asarray(offsets, float)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"`duration` must be > 0 s; got {duration!r}.")
    if (
        offsets.ndim != 2
        or offsets.shape[0] != times.shape[0]
        or (offsets.shape[1] not in (3, 6))
    ):
        raise ValueError(
            f"`offsets` must have shape ({times.shape[0]}, 3) or "
            f"({times.shape[0]}, 6) (one row per time); got {offsets.shape}."
        )
    s = np.clip((times - times[0]) / duration, 0.0, 1.0)
    return offsets * (np.sin(0.5 * np.pi * s) ** 2)[:, None]


def _motion_key(key):
    """('point', ID), ('body', ID) or ('rod', ID) of a `motion` dict key: a point
    ID, or "body<n>" / "rod<n>" (any case)."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        return ("point", int(key))
    parts = _decompose(str(key)) or []
    if len(parts) == 2 and parts[0] in ("BODY", "B", "ROD", "R") and parts[1].isdigit():
        return ("body" if parts[0][0] == "B" else "rod", int(parts[1]))
    raise ValueError(
        f"`motion` key {key!r} is not valid; valid: a coupled point's ID, "
        "'body<n>' or 'rod<n>' of a coupled body or rod."
    )


def deck_scene(
    deck: MoorDynDeck,
    motion=None,
    t1=None,
    t0=None,
    static=True,
    free_points="hold",
    axial_drag="surface",
) -> Scene:
    """The `Scene` of a parsed deck.

    **Arguments:**

    - `motion`: None (coupled objects held at their deck poses); a motion table
      path or `(times, offsets (K, 3) or (K, 6))`: a translation added to every
      coupled point's deck position and a pose offset (translation, then
      MoorDyn's Euler angles in rad) of every coupled or coupled-pinned body and
      rod (a coupled point has no orientation: non-zero rotations need the
      fairleads on a coupled body); or a dict {point ID: any jaxstring end
      condition, "body<n>" or "rod<n>": a `RigidMotion`}.
    - `t0`, `t1`: the time span, s (default: the motion table's span, else 0 and
      10 s).
    - `static`: start from the static equilibrium at t0 (`equilibrium`: the
      lines settle, bodies and rods held at their deck poses), else from the
      catenary guess (`initial_shape`; MoorDyn's start with TmaxIC 0).
    - `free_points`: "hold" (free points held too) or "solve".
    - `axial_drag`: the reference area of the line types' CdAx per unit length,
      `"surface"` (pi d, MoorDyn's) or `"diameter"` (d, DNV-OS-E301's and
      OrcaFlex's chain convention; see `Drag`).
    """
    from .._validate import check_choice
    from .models import initial_shape

    check_choice("axial_drag", axial_drag, ("surface", "diameter"))
    o = deck.options
    times = None
    if isinstance(motion, (str, os.PathLike)):
        times, offsets = read_motion(motion)
    elif isinstance(motion, tuple):
        times, offsets = (np.asarray(m, float) for m in motion)
        if offsets.ndim != 2 or offsets.shape[1] not in (3, 6):
            raise ValueError(
                f"`motion` offsets must have shape (K, 3) or (K, 6); got "
                f"{offsets.shape}."
            )
    coupled = {("point", p["id"]) for p in deck.points if p["kind"] == "coupled"}
    coupled |= {("body", b["id"]) for b in deck.bodies
                if b["kind"] in ("coupled", "coupled_pinned")}  # fmt: skip
    coupled |= {("rod", r["id"]) for r in deck.rods
                if r["kind"] in ("coupled", "coupled_pinned")}  # fmt: skip
    given = {}
    if isinstance(motion, dict):
        given = {_motion_key(k): v for k, v in motion.items()}
        unknown = sorted(set(given) - coupled)
        if unknown:
            raise ValueError(
                f"`motion` names {unknown} that are not coupled (coupled: "
                f"{sorted(coupled)})."
            )
        for k, v in given.items():
            if k[0] != "point" and not isinstance(v, RigidMotion):
                raise ValueError(
                    f"`motion` for {k[0]} {k[1]} must be a RigidMotion; got {v!r}."
                )
    table6 = None
    smoothing = 0.0
    if times is not None:
        # Smooth the knots over one sample (a box filter: C1 motion for the
        # adaptive solvers), and carry the last sample's velocity one sample on,
        # so that the table's end is not a sudden stop.
        smoothing = float(np.min(np.diff(times)))
        times = np.append(times, 2 * times[-1] - times[-2])
        offsets = np.concatenate([offsets, 2 * offsets[-1:] - offsets[-2:-1]])
        table6 = np.zeros((len(times), 6))
        table6[:, : offsets.shape[1]] = offsets
        if np.any(table6[:, 3:] != 0) and any(k[0] == "point" for k in coupled):
            raise ValueError(
                "`motion`: the table has rotations (columns 5-7) and the deck has "
                "coupled points, which have no orientation; valid: zero rotations, "
                "or the fairleads as points on a coupled body."
            )

    def rigid_motion(key):
        if key in given:
            return given[key]
        if table6 is not None:
            return RigidMotion(times, table6, smoothing)
        return None

    body_index = {b["id"]: k for k, b in enumerate(deck.bodies)}
    points, index = [], {}
    for p in deck.points:
        index[p["id"]] = len(points)
        pos = np.asarray(p["position"], float)
        if p["kind"] == "free":
            points.append(FreePoint(pos, p["mass"], p["volume"], p["CdA"], p["Ca"]))
        elif p["kind"] == "body":
            points.append(BodyPoint(body_index[p["body"]], pos, p["mass"],
                                    p["volume"], p["CdA"], p["Ca"]))  # fmt: skip
        elif ("point", p["id"]) in given:
            points.append(given[("point", p["id"])])
        elif p["kind"] == "coupled" and times is not None:
            points.append(PrescribedEnd(times, pos + table6[:, :3], smoothing))
        else:
            points.append(FixedEnd(pos))
    bodies = tuple(_deck_body(b) for b in deck.bodies)
    body_motions = tuple(
        rigid_motion(("body", b["id"])) if b["kind"] != "fixed" else None
        for b in deck.bodies
    )
    if not any(m is not None for m in body_motions):
        body_motions = ()
    rods = _deck_rods(deck, rigid_motion)

    def end(e):
        return RodEnd(e[0] - 1, e[1]) if isinstance(e, tuple) else index[e]

    col = lambda key: f64([deck.types[ln["type"]][key] for ln in deck.lines])
    EI = col("EI")
    model = LineNetwork(
        points=tuple(points),
        attach=tuple((end(ln["a"]), end(ln["b"])) for ln in deck.lines),
        segments=tuple(ln["segments"] for ln in deck.lines),
        L=f64([ln["L"] for ln in deck.lines]),
        d=col("d"),
        w=col("w"),
        EA=col("EA"),
        BA=col("BA"),
        Cd=col("Cd"),
        Ca=col("Ca"),
        CdAx=col("CdAx"),
        CaAx=col("CaAx"),
        line_ids=tuple(ln["id"] for ln in deck.lines),
        point_ids=tuple(p["id"] for p in deck.points),
        # bending is traced only for a deck that names some
        EI=EI if bool(np.any(np.asarray(EI) > 0)) else None,
        rods=rods,
        bodies=bodies,
        body_motions=body_motions,
    )
    effects = [Gravity(), Buoyancy(), Drag(axial_area=axial_drag)]
    if o["rho"] == 0:
        # a deck in vacuum (WtrDnsty 0): no buoyancy, drag or added mass is traced
        effects = [Gravity()]
        model = _without_added_mass(model)
    if o["depth"] > 0:
        effects.append(
            Seabed(
                depth=o["depth"],
                kBot=o["kBot"],
                cBot=o["cBot"],
                friction=o["friction"],
                fric_damp=o["fric_damp"],
            )
        )
    effects = tuple(effects)
    env = Environment(g=o["g"], rho_water=o["rho"] if o["rho"] > 0 else 1025.0)
    if t0 is None:
        t0 = float(times[0]) if times is not None else 0.0
    if t1 is None:
        t1 = float(times[-2]) if times is not None else t0 + 10.0
    if static:
        y0, info = equilibrium(model, effects, env, t0, free_points=free_points)
    else:
        y0 = initial_shape(model, effects, env, t0)
    name = os.path.splitext(os.path.basename(deck.path))[0]
    scene = Scene(model, effects, y0, t1=t1, t0=t0, name=name, env=env)
    if static:
        _REST_TENSIONS.append((scene, info["tension_a"], info["tension_b"]))
    return scene


def _without_added_mass(model):
    """The network with every added-mass coefficient zero (a deck in vacuum)."""
    zero = jnp.zeros_like(model.Ca)
    model = eqx.tree_at(lambda m: (m.Ca, m.CaAx), model, (zero, zero))
    for i, p in enumerate(model.points):
        if isinstance(p, (FreePoint, BodyPoint)):
            model = eqx.tree_at(lambda m: m.points[i].Ca, model, jnp.zeros(()))
    for r in range(len(model.rods)):
        model = eqx.tree_at(lambda m: (m.rods[r].Ca, m.rods[r].CaEnd), model,
                            (jnp.zeros(()), jnp.zeros(())))  # fmt: skip
    for b in range(len(model.bodies)):
        model = eqx.tree_at(lambda m: m.bodies[b].Ca, model, jnp.zeros(3))
    return model


_BODY_KIND = {"fixed": "fixed", "free": "free", "coupled": "coupled",
              "coupled_pinned": "pinned"}  # fmt: skip


def _deck_body(b) -> Body:
    """A deck's body as a `Body`. MoorDyn zeroes the mass, volume, inertia, drag
    and added mass of fixed and coupled bodies (only what is on them counts)."""
    kind = _BODY_KIND[b["kind"]]
    inert = b["kind"] in ("fixed", "coupled")
    values = {
        "mass": 0.0 if inert else b["mass"],
        "cg": b["cg"],
        "inertia": [0.0] * 3 if inert else b["inertia"],
        "volume": 0.0 if inert else b["volume"],
        "CdA": [0.0] * 6 if inert else b["CdA"],
        "Ca": [0.0] * 3 if inert else b["Ca"],
    }
    name = f"body {b['id']}"
    if kind == "free" and values["mass"] == 0 and values["volume"] == 0:
        # a free body whose inertia is all in the points and rods on it
        # (MoorDyn's orbitalBody; parse_moordyn checks that there are some):
        # built with a placeholder mass, which is then set to zero
        body = Body(kind, b["position"], b["angles"], **{**values, "mass": 1.0},
                    name=name)  # fmt: skip
        return eqx.tree_at(lambda x: x.mass, body, jnp.zeros(()))
    return Body(kind, b["position"], b["angles"], **values, name=name)


def _deck_rods(deck, rigid_motion) -> tuple:
    """The deck's rods as `Rod`s."""
    body_index = {b["id"]: k for k, b in enumerate(deck.bodies)}
    rods = []
    for r in deck.rods:
        if r["segments"] == 0:
            raise ValueError(
                f"{deck.path}: line {r['line']}: rod {r['id']} has NumSegs 0 (a "
                "zero-length joint), which is not simulated; valid: NumSegs >= 1."
            )
        t = deck.rod_types[r["type"]]
        motion = None
        if r["kind"] in ("coupled", "coupled_pinned"):
            motion = rigid_motion(("rod", r["id"]))
        rods.append(
            Rod(
                r["end_a"],
                r["end_b"],
                r["segments"],
                t["d"],
                t["w"],
                t["Cd"],
                t["Ca"],
                t["CdEnd"],
                t["CaEnd"],
                kind=r["kind"],
                body=None if r["body"] is None else body_index[r["body"]],
                motion=motion,
            )  # fmt: skip
        )
    return tuple(rods)


def read_moordyn(path, **options) -> Scene:
    """Read a MoorDyn v2 deck into a `Scene` at static equilibrium: `deck_scene`
    of `parse_moordyn(path)`, with `deck_scene`'s keyword options (`motion`,
    `t1`, `t0`, `static`, `free_points`, `axial_drag`)."""
    options = options_of(deck_scene, "read_moordyn", options)
    return deck_scene(parse_moordyn(path), **options)


same_signature(read_moordyn, deck_scene)


@eager_jit(tiered=True)
def _rest_observables(scene):
    ta, tb = rest_end_tensions(
        scene.model, scene.effects, scene.env, scene.t0, scene.y0[:, :3]
    )
    return {"tension_a": ta, "tension_b": tb}


# The end tensions the static solve of `deck_scene` found for the last few scenes
# it built: `static_tensions` of such a scene, unchanged (the same initial state,
# model, effects, environment and start time objects), reads them instead of
# compiling `_rest_observables`.
_REST_TENSIONS = collections.deque(maxlen=8)  # (scene, tension_a, tension_b)


def _remembered_rest_tensions(scene):
    fields = lambda s: (s.y0, s.model, s.effects, s.env, s.t0)  # noqa: E731
    for sc, ta, tb in reversed(_REST_TENSIONS):
        if all(a is b for a, b in zip(fields(sc), fields(scene))):
            return {"tension_a": ta, "tension_b": tb}
    return None


def static_tensions(scene: Scene) -> dict:
    """Per line ID, the (end A, end B) tension magnitudes of the scene's initial
    state, N: the force each line exerts on its end points (segment tension plus
    the end node's loads), at rest. For a scene from `read_moordyn` the initial
    state is the static equilibrium."""
    model = scene.model
    if not isinstance(model, LineNetwork):
        raise ValueError(
            f"`scene` must hold a LineNetwork; got {type(model).__name__}."
        )
    obs = _remembered_rest_tensions(scene) or _rest_observables(scene)
    ids = model.line_ids or tuple(range(1, model.n_lines + 1))
    ta, tb = np.asarray(obs["tension_a"]), np.asarray(obs["tension_b"])
    return {lid: (float(ta[k]), float(tb[k])) for k, lid in enumerate(ids)}


# ---------------------------------------------------------------------------
# Output channels


def output_channels(traj, scene: Scene) -> dict:
    """MoorDyn-style channels of a trajectory (MoorDyn's names and units):

    - `Time`, s;
    - per line: `FAIRTEN<id>` (end B) and `ANCHTEN<id>` (end A) tension
      magnitudes, N; per line node `L<id>N<i>P{X,Y,Z}` positions, m;
    - per rod (IDs 1, 2, ... in deck order): `ROD<id>P{X,Y,Z}` (end A, m),
      `ROD<id>R{X,Y}` (the axis' inclination phi from +z and heading beta as
      -phi sin(beta), phi cos(beta), deg), `ROD<id>V{X,Y,Z}` (m/s),
      `ROD<id>RV{X,Y,Z}` (deg/s), `ROD<id>A{X,Y,Z}` (m/s^2),
      `ROD<id>RA{X,Y,Z}` (deg/s^2), `ROD<id>F{X,Y,Z}` (N) and `ROD<id>M{X,Y,Z}`
      (N m, about end A: everything on the rod, less its inertia for a coupled
      rod), `ROD<id>TENA`, `ROD<id>TENB` (the lines' end forces on each end, N),
      `ROD<id>N<i>P{X,Y,Z}` (nodes, m);
    - per body (IDs 1, 2, ... in deck order): `BODY<id>P{X,Y,Z}` (the
      reference point, m), `BODY<id>R{X,Y,Z}` (MoorDyn's Euler angles, deg),
      `BODY<id>V{X,Y,Z}` (m/s), `BODY<id>RV{X,Y,Z}` (deg/s),
      `BODY<id>A{X,Y,Z}` (m/s^2), `BODY<id>RA{X,Y,Z}` (deg/s^2),
      `BODY<id>F{X,Y,Z}` (N), `BODY<id>M{X,Y,Z}` (N m, about the reference
      point) and `BODY<id>TEN` (the force's magnitude, N): MoorDyn's getFnet
      (`LineNetwork.observables`).

    Returns an ordered dict name -> `(T,)`."""
    model = scene.model
    ids = model.line_ids or tuple(range(1, model.n_lines + 1))
    obs = traj.obs
    ch = {"Time": np.asarray(traj.ts)}
    ta, tb = np.asarray(obs["tension_a"]), np.asarray(obs["tension_b"])
    for k, lid in enumerate(ids):
        ch[f"FAIRTEN{lid}"] = tb[:, k]
        ch[f"ANCHTEN{lid}"] = ta[:, k]
    nodes = np.asarray(obs["nodes"])
    for k, lid in enumerate(ids):
        _node_channels(ch, f"L{lid}", nodes, model.line_nodes(k))
    if model.rods:
        get = lambda key: np.asarray(obs[key])
        q = get("rod_axis")
        phi = np.arctan2(np.hypot(q[..., 0], q[..., 1]), q[..., 2])
        level = np.hypot(q[..., 0], q[..., 1]) < 1e-6
        beta = np.where(level, 0.0, np.arctan2(q[..., 1], q[..., 0]))
        deg = 180.0 / np.pi
        rx, ry = -phi * np.sin(beta) * deg, phi * np.cos(beta) * deg
        force, ten = get("rod_force"), get("rod_end_tension")
        rnodes = get("rod_nodes")
        for r in range(len(model.rods)):
            p = f"ROD{r + 1}"
            for c, axis in enumerate("XYZ"):
                ch[f"{p}P{axis}"] = get("rod_end_a")[:, r, c]
            ch[f"{p}RX"], ch[f"{p}RY"] = rx[:, r], ry[:, r]
            _rigid_channels(ch, p, get, "rod", r, force, ("V", "RV", "A", "RA"))
            ch[f"{p}TENA"], ch[f"{p}TENB"] = ten[:, r, 0], ten[:, r, 1]
            _node_channels(ch, p, rnodes, model.rod_nodes(r))
    if model.bodies:
        get = lambda key: np.asarray(obs[key])
        force = get("body_force")
        for b in range(len(model.bodies)):
            p = f"BODY{b + 1}"
            names = ("P", "R", "V", "RV", "A", "RA")
            _rigid_channels(ch, p, get, "body", b, force, names)
            ch[f"{p}TEN"] = np.linalg.norm(force[:, b, :3], axis=1)
    return ch


def channel_unit(name: str) -> str:
    """MoorDyn's unit of an output channel name, e.g. `"(m)"` for `L1N3PX`."""
    if name == "Time":
        return "(s)"
    if "TEN" in name:
        return "(N)"
    tail = re.sub(r"^(L|LINE|P|POINT|R|ROD|B|BODY)\d+(N(\d+|A|B))?", "", name)
    return {"PX": "(m)", "PY": "(m)", "PZ": "(m)", "RX": "(deg)", "RY": "(deg)",
            "RZ": "(deg)", "VX": "(m/s)", "VY": "(m/s)", "VZ": "(m/s)",
            "RVX": "(deg/s)", "RVY": "(deg/s)", "RVZ": "(deg/s)", "AX": "(m/s^2)",
            "AY": "(m/s^2)", "AZ": "(m/s^2)", "RAX": "(deg/s^2)",
            "RAY": "(deg/s^2)", "RAZ": "(deg/s^2)", "FX": "(N)", "FY": "(N)",
            "FZ": "(N)", "MX": "(Nm)", "MY": "(Nm)", "MZ": "(Nm)",
            "T": "(N)"}.get(tail, "(-)")  # fmt: skip


_RIGID_CHANNELS = {
    "P": ("position", 1.0),
    "R": ("angles", 180.0 / np.pi),
    "V": ("velocity", 1.0),
    "RV": ("omega", 180.0 / np.pi),
    "A": ("acceleration", 1.0),
    "RA": ("alpha", 180.0 / np.pi),
}
"""MoorDyn's rigid-object channel -> (observable after `rod_`/`body_`, scale to
MoorDyn's units: degrees for rotations)."""


def _node_channels(ch, prefix, nodes, rows):
    """Add the channels `<prefix>N<i>P<X|Y|Z>` of the nodes `rows` of `nodes`
    `(T, M, 3)` to `ch`."""
    for i, m in enumerate(rows):
        for c, axis in enumerate("XYZ"):
            ch[f"{prefix}N{i}P{axis}"] = nodes[:, m, c]


def _rigid_channels(ch, prefix, get, kind, i, force, names):
    """A rod's or body's kinematic channels `names` (keys of `_RIGID_CHANNELS`),
    then its force and moment (F, M), in MoorDyn's order, into `ch`."""
    for name in names:
        key, scale = _RIGID_CHANNELS[name]
        for c, axis in enumerate("XYZ"):
            ch[f"{prefix}{name}{axis}"] = scale * get(f"{kind}_{key}")[:, i, c]
    for c, axis in enumerate("XYZ"):
        ch[f"{prefix}F{axis}"] = force[:, i, c]
    for c, axis in enumerate("XYZ"):
        ch[f"{prefix}M{axis}"] = force[:, i, 3 + c]


def write_outputs(traj, scene: Scene, stem) -> tuple[str, str]:
    """Write the channels (`output_channels`) as `<stem>.out` (tab-separated: a
    header row of names, a row of units, then one row per saved time) and
    `<stem>.npz`. Returns both paths."""
    ch = output_channels(traj, scene)
    names = list(ch)
    units = [channel_unit(n) for n in names]
    data = np.stack([ch[n] for n in names], axis=1)
    os.makedirs(os.path.dirname(os.fspath(stem)) or ".", exist_ok=True)
    out = f"{stem}.out"
    with open(out, "w") as f:
        f.write("\t".join(names) + "\n")
        f.write("\t".join(units) + "\n")
        for row in data:
            f.write("\t".join(f"{v:.6e}" for v in row) + "\n")
    npz = f"{stem}.npz"
    np.savez(npz, **ch)
    return out, npz
