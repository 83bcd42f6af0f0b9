"""MoorDyn v2 input decks in, MoorDyn-style output channels out.

`parse_moordyn(path)` reads the LINE TYPES (or LINE DICTIONARY), POINTS (or POINT /
CONNECTION / NODE PROPERTIES), LINES (or LINE PROPERTIES) and OPTIONS sections of a
MoorDyn v2 deck into a `MoorDynDeck`; `read_moordyn(path, ...)` builds the
`jaxstring.Scene` at static equilibrium (jaxstring's own solve: catenary start and
pseudo-transient Newton, not MoorDyn's `.ic` snapshot). Anything the model does not
have -- rods, bodies, wave kinematics, bending stiffness, non-linear stiffness
tables, unknown options -- raises a ValueError naming the file, the line and the
column; nothing is skipped silently.

Conventions (MoorDyn's): z up with the still-water surface at z = 0; the seabed at
z = -WtrDpth; g = 9.80665 m/s^2, water density 1025 kg/m^3, kBot = 3e6 Pa/m,
cBot = 3e5 Pa s/m, FrictionCoefficient = 0 unless the deck says otherwise; a
negative BA is minus the damping ratio; a negative UnstrLen scales the distance
between the line's ends. End B of a line is its fairlead end (MoorDyn's FAIRTEN
channel), end A its anchor end (ANCHTEN).
"""

import dataclasses
import math
import os

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._environment import Environment
from .._scene import Scene
from ..chain import Buoyancy, Drag, FixedEnd, Gravity, PrescribedEnd
from .effects import Seabed
from .models import FreePoint, LineNetwork, equilibrium


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
            if f.endswith(".txt") and f != "LICENSE.txt"
        )
        raise ValueError(f"unknown case {name!r}; valid: {', '.join(known)}.")
    return path


_TYPE_COLUMNS = ("Name", "Diam", "Mass/m", "EA", "BA/-zeta", "EI", "Cd", "Ca", "CdAx",
                 "CaAx")  # fmt: skip
_POINT_COLUMNS = ("ID", "Type", "X", "Y", "Z", "Mass", "Volume", "CdA", "Ca")
_LINE_COLUMNS = ("ID", "LineType", "AttachA", "AttachB", "UnstrLen", "NumSegs")

_SECTIONS = {
    "LINE TYPES": "types",
    "LINE DICTIONARY": "types",
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
_UNSUPPORTED_SECTIONS = (
    "ROD TYPES",
    "ROD DICTIONARY",
    "RODS",
    "ROD PROPERTIES",
    "ROD LIST",
    "BODIES",
    "BODY PROPERTIES",
    "BODY LIST",
    "FAILURE",
    "EXTERNAL LOADS",
    "MOTIONS",
)
_POINT_KINDS = {
    "fixed": "fixed",
    "anchor": "fixed",
    "vessel": "coupled",
    "coupled": "coupled",
    "fairlead": "coupled",
    "free": "free",
    "connect": "free",
    "point": "free",
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
    "writelog", "dtm", "cfl", "tscheme", "dtic", "tmaxic", "cdscaleic", "threshic",
    "icgendynamic", "fileic", "disableouttime", "dtout", "writeunits", "dtwave",
    "icdfac", "icthresh", "ictmax", "fricdamp_ic", "disableoutput",
}  # fmt: skip
# Options whose non-zero value asks for something the model does not have.
_ZERO_ONLY_OPTIONS = {"waterkin", "currents", "waves", "seafloor", "inertialf",
                      "inertialf_rampt", "viv"}  # fmt: skip


@dataclasses.dataclass
class MoorDynDeck:
    """A parsed MoorDyn v2 deck.

    **Fields:** `path`; `types` (name -> dict of d, w, EA, BA, Cd, Ca, CdAx, CaAx);
    `points` (list of dicts: id, kind 'fixed' | 'coupled' | 'free', position, mass,
    volume, CdA, Ca); `lines` (list of dicts: id, type, a, b (point ids), L,
    segments); `options` (the physics values after MoorDyn's defaults: g, rho,
    depth, kBot, cBot, friction, fric_damp, stat_dyn_fric_scale); `numerics` (the
    deck's own numerical options, e.g. dtM, cfl, tScheme, as text); `outputs`
    (the OUTPUTS section's channel names, reported, not needed).
    """

    path: str
    types: dict
    points: list
    lines: list
    options: dict
    numerics: dict
    outputs: list


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


def _number(where, fields, i, name, positive=False, nonnegative=False):
    if i >= len(fields):
        raise where.error(len(fields) - 1, fields, f"missing column {i + 1} ({name})")
    text = fields[i]
    try:
        v = float(text.replace("D", "E").replace("d", "e"))
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


def _integer(where, fields, i, name, minimum):
    v = _number(where, fields, i, name)
    if v != int(v) or v < minimum:
        raise where.error(
            i, fields, f"column {i + 1} ({name}) must be an integer >= {minimum}"
        )
    return int(v)


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
    types, points, lines, outputs = {}, [], [], []
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
                    f"section {kind[1]!r} {what} (jaxstring reads LINE TYPES, POINTS, "
                    "LINES, OPTIONS and OUTPUTS; rods, bodies and wave kinematics are "
                    "not modelled)",
                )
            section = _SECTIONS[kind]
            if section in seen and section != "outputs":
                raise where.error(0, line.split(), f"section {kind!r} appears twice")
            seen.add(section)
            skip = 2 if section in ("types", "points", "lines") else 0
            continue
        if section is None or not line.strip():
            continue
        if skip:
            skip -= 1
            continue
        fields = line.split()
        if section == "types":
            _type_row(where, fields, types)
        elif section == "points":
            _point_row(where, fields, points)
        elif section == "lines":
            lines.append((where, fields))
        elif section == "options":
            _option_row(where, fields, raw_options, numerics)
        elif section == "outputs":
            if line.strip().upper() != "END":
                outputs.extend(fields)
    where_end = _Where(path, len(text), text[-1] if text else "")
    for sec, label in (
        ("types", "LINE TYPES"),
        ("points", "POINTS"),
        ("lines", "LINES"),
    ):
        if sec not in seen:
            raise where_end.error(0, [], f"the deck has no {label} section")
    ids = {p["id"]: p for p in points}
    parsed = [_line_row(w, f, types, ids) for w, f in lines]
    if not parsed:
        raise where_end.error(0, [], "the LINES section lists no line")
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
    return MoorDynDeck(path, types, points, parsed, options, numerics, outputs)


def _type_row(where, fields, types):
    _need_columns(where, fields, _TYPE_COLUMNS, "a line type")
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
    EI = _number(where, fields, 5, "EI", nonnegative=True)
    if EI != 0:
        raise where.error(5, fields, "bending stiffness EI > 0 is not supported")
    for i, key in zip(range(6, 10), ("Cd", "Ca", "CdAx", "CaAx")):
        t[key] = _number(where, fields, i, key, nonnegative=True)
    for i in range(10, len(fields)):
        v = fields[i]
        if not _is_number(v) or float(v) != 0.0:
            raise where.error(
                i,
                fields,
                f"column {i + 1} ({v!r}): extra line-type properties (lift, VIV, "
                "visco-elastic) are not supported",
            )
    if name in types:
        raise where.error(0, fields, f"line type {name!r} is defined twice")
    types[name] = t


def _is_number(text):
    try:
        float(text)
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


def _point_row(where, fields, points):
    _need_columns(where, fields, _POINT_COLUMNS, "a point")
    pid = _integer(where, fields, 0, "ID", 0)
    kind = _POINT_KINDS.get(fields[1].lower())
    if kind is None:
        raise where.error(
            1,
            fields,
            f"point type {fields[1]!r} is not supported (Fixed/Anchor, Vessel/Coupled/"
            "Fairlead, Free/Connect; points on bodies are not modelled)",
        )
    if any(p["id"] == pid for p in points):
        raise where.error(0, fields, f"point ID {pid} is defined twice")
    pos = [_number(where, fields, i, n) for i, n in zip((2, 3, 4), "XYZ")]
    points.append(
        {
            "id": pid,
            "kind": kind,
            "position": pos,
            "mass": _number(where, fields, 5, "Mass", nonnegative=True),
            "volume": _number(where, fields, 6, "Volume", nonnegative=True),
            "CdA": _number(where, fields, 7, "CdA", nonnegative=True),
            "Ca": _number(where, fields, 8, "Ca", nonnegative=True),
        }
    )


def _line_row(where, fields, types, points):
    _need_columns(where, fields, _LINE_COLUMNS, "a line", " [LineOutputs]")
    lid = _integer(where, fields, 0, "ID", 0)
    if fields[1] not in types:
        raise where.error(
            1, fields, f"line type {fields[1]!r} is not in LINE TYPES ({list(types)})"
        )
    ends = []
    for i, name in ((2, "AttachA"), (3, "AttachB")):
        text = fields[i]
        if not text.isdigit():
            raise where.error(
                i,
                fields,
                f"column {i + 1} ({name}) must be a point ID; {text!r} (rods and "
                "bodies) is not supported",
            )
        if int(text) not in points:
            raise where.error(i, fields, f"point {text} is not in POINTS")
        ends.append(int(text))
    if ends[0] == ends[1]:
        raise where.error(3, fields, "a line cannot join a point to itself")
    L = _number(where, fields, 4, "UnstrLen")
    if L == 0:
        raise where.error(4, fields, "column 5 (UnstrLen) must not be 0")
    if L < 0:  # MoorDyn: a factor on the distance between the ends
        pa = np.asarray(points[ends[0]]["position"])
        pb = np.asarray(points[ends[1]]["position"])
        L = -L * float(np.linalg.norm(pb - pa))
    N = _integer(where, fields, 5, "NumSegs", 1)
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
        if target in ("rho", "g", "fric_damp") and v <= 0:
            raise where.error(0, fields, f"option {name} must be > 0; got {v:g}")
        if target in ("kBot", "cBot", "friction", "depth") and v < 0:
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
    """A motion table: whitespace-separated rows `t x y z [rx ry rz]` (s, m, rad;
    the rotations must be 0). Returns `(times (K,), offsets (K, 3))`."""
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
            "(t x y z rx ry rz with zero rotations)."
        )
    if data.shape[1] == 7 and np.any(data[:, 4:] != 0):
        raise ValueError(
            f"`motion`: {path} has non-zero rotations (columns 5-7); only "
            "translations of the coupled points are supported."
        )
    t = data[:, 0]
    if data.shape[0] < 2 or np.any(np.diff(t) <= 0):
        raise ValueError(f"`motion`: the times in {path} must increase strictly.")
    return t, data[:, 1:4]


def ramp_in(times, offsets, duration):
    """A motion table's offsets ramped in over its first `duration` seconds:
    times sin^2(pi/2 (t - t0)/duration), so that a table that starts at full
    speed (such as ZZP1_A1 at t = -10 s) starts from rest with no step in the
    point's velocity. Returns the offsets `(K, 3)`, m."""
    times = np.asarray(times, float)
    offsets = np.asarray(offsets, float)
    if not (np.isfinite(duration) and duration > 0):
        raise ValueError(f"`duration` must be > 0 s; got {duration!r}.")
    if offsets.shape != (times.shape[0], 3):
        raise ValueError(
            f"`offsets` must have shape ({times.shape[0]}, 3) (one row per time); "
            f"got {offsets.shape}."
        )
    s = np.clip((times - times[0]) / duration, 0.0, 1.0)
    return offsets * (np.sin(0.5 * np.pi * s) ** 2)[:, None]


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

    - `motion`: None (coupled points held at their deck positions), a motion table
      path or `(times, offsets (K, 3))`: a translation added to every coupled
      point's deck position, or a dict {point ID: any jaxstring end condition}.
    - `t0`, `t1`: the time span, s (default: the motion table's span, else 0 and
      10 s).
    - `static`: start from the static equilibrium at t0 (`equilibrium`), else from
      the catenary guess (`initial_shape`).
    - `free_points`: "hold" (MoorDyn's initial condition) or "solve".
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
    coupled = [p for p in deck.points if p["kind"] == "coupled"]
    ends = {}
    if isinstance(motion, dict):
        unknown = set(motion) - {p["id"] for p in coupled}
        if unknown:
            raise ValueError(
                f"`motion` names points {sorted(unknown)} that are not coupled "
                f"(coupled: {[p['id'] for p in coupled]})."
            )
        ends = dict(motion)
    points, index = [], {}
    smoothing = 0.0
    if times is not None:
        # Smooth the knots over one sample (a box filter: C1 motion for the
        # adaptive solvers), and carry the last sample's velocity one sample on,
        # so that the table's end is not a sudden stop.
        smoothing = float(np.min(np.diff(times)))
        times = np.append(times, 2 * times[-1] - times[-2])
        offsets = np.concatenate([offsets, 2 * offsets[-1:] - offsets[-2:-1]])
    for p in deck.points:
        index[p["id"]] = len(points)
        pos = np.asarray(p["position"], float)
        if p["kind"] == "free":
            points.append(FreePoint(pos, p["mass"], p["volume"], p["CdA"], p["Ca"]))
        elif p["id"] in ends:
            points.append(ends[p["id"]])
        elif p["kind"] == "coupled" and times is not None:
            points.append(PrescribedEnd(times, pos + offsets, smoothing))
        else:
            points.append(FixedEnd(pos))
    col = lambda key: jnp.asarray([deck.types[ln["type"]][key] for ln in deck.lines])
    model = LineNetwork(
        points=tuple(points),
        attach=tuple((index[ln["a"]], index[ln["b"]]) for ln in deck.lines),
        segments=tuple(ln["segments"] for ln in deck.lines),
        L=jnp.asarray([ln["L"] for ln in deck.lines]),
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
    )
    effects = [Gravity(), Buoyancy(), Drag(axial_area=axial_drag)]
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
    env = Environment(g=o["g"], rho_water=o["rho"])
    if t0 is None:
        t0 = float(times[0]) if times is not None else 0.0
    if t1 is None:
        t1 = float(times[-2]) if times is not None else t0 + 10.0
    if static:
        y0, _ = equilibrium(model, effects, env, t0, free_points=free_points)
    else:
        y0 = initial_shape(model, effects, env, t0)
    name = os.path.splitext(os.path.basename(deck.path))[0]
    return Scene(model, effects, y0, t1=t1, t0=t0, name=name, env=env)


def read_moordyn(
    path, motion=None, t1=None, t0=None, static=True, axial_drag="surface"
) -> Scene:
    """Read a MoorDyn v2 deck into a `Scene` at static equilibrium (see
    `parse_moordyn` and `deck_scene` for the arguments)."""
    return deck_scene(
        parse_moordyn(path),
        motion=motion,
        t1=t1,
        t0=t0,
        static=static,
        axial_drag=axial_drag,
    )


@eqx.filter_jit
def _rest_observables(scene):
    model = scene.model
    y = scene.y0.at[:, 3:].set(0.0)
    st = model._state(scene.t0, y, scene.effects, scene.env)
    st = eqx.tree_at(lambda s: s.held_acc, st, jnp.zeros_like(st.held_acc))
    zero = jnp.zeros((model.topology.n_state, 3))
    fa, fb = model.end_forces(st, zero)
    return {"tension_a": jnp.linalg.norm(fa, axis=1),
            "tension_b": jnp.linalg.norm(fb, axis=1)}  # fmt: skip


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
    obs = _rest_observables(scene)
    ids = model.line_ids or tuple(range(1, model.n_lines + 1))
    ta, tb = np.asarray(obs["tension_a"]), np.asarray(obs["tension_b"])
    return {lid: (float(ta[k]), float(tb[k])) for k, lid in enumerate(ids)}


# ---------------------------------------------------------------------------
# Output channels


def output_channels(traj, scene: Scene) -> dict:
    """MoorDyn-style channels of a trajectory: `Time`; per line `FAIRTEN<id>`
    (end B) and `ANCHTEN<id>` (end A) tension magnitudes, N; per line node
    `L<id>N<i>P{X,Y,Z}` positions, m. Returns an ordered dict name -> `(T,)`."""
    model = scene.model
    ids = model.line_ids or tuple(range(1, model.n_lines + 1))
    ch = {"Time": np.asarray(traj.ts)}
    ta, tb = np.asarray(traj.obs["tension_a"]), np.asarray(traj.obs["tension_b"])
    for k, lid in enumerate(ids):
        ch[f"FAIRTEN{lid}"] = tb[:, k]
        ch[f"ANCHTEN{lid}"] = ta[:, k]
    nodes = np.asarray(traj.obs["nodes"])
    for k, lid in enumerate(ids):
        for i, m in enumerate(model.line_nodes(k)):
            for c, axis in enumerate("XYZ"):
                ch[f"L{lid}N{i}P{axis}"] = nodes[:, m, c]
    return ch


def write_outputs(traj, scene: Scene, stem) -> tuple[str, str]:
    """Write the channels (`output_channels`) as `<stem>.out` (tab-separated: a
    header row of names, a row of units, then one row per saved time) and
    `<stem>.npz`. Returns both paths."""
    ch = output_channels(traj, scene)
    names = list(ch)
    units = ["(s)"] + ["(N)" if n.endswith(("TEN", "TEN1")) or "TEN" in n else "(m)"
                       for n in names[1:]]  # fmt: skip
    data = np.stack([ch[n] for n in names], axis=1)
    out = f"{stem}.out"
    with open(out, "w") as f:
        f.write("\t".join(names) + "\n")
        f.write("\t".join(units) + "\n")
        for row in data:
            f.write("\t".join(f"{v:.6e}" for v in row) + "\n")
    npz = f"{stem}.npz"
    np.savez(npz, **ch)
    return out, npz
