"""MoorDyn decks with bodies, rods and bending stiffness: every column of the
BODIES, RODS and ROD TYPES sections, attachment keywords, points on bodies, line
ends on rod ends; a ValueError naming the file, line, column and valid range for
a malformed row (and exit code 2 from `jaxstring run moordyn`)."""

import math

import numpy as np
import pytest

from jaxstring import lines
from jaxstring.cli.main import main


def _rows(name):
    with open(lines.case_path(name)) as f:
        return f.read().splitlines()


def _write(tmp_path, rows):
    path = tmp_path / "deck.txt"
    path.write_text("\n".join(rows))
    return str(path)


def _row(rows, start):
    return next(k for k, r in enumerate(rows) if r.split()[:1] == [start]
                or r.startswith(start))  # fmt: skip


def _column(text, i):
    """1-based character column of the whitespace-separated field i of text."""
    pos = 0
    for k, f in enumerate(text.split()):
        pos = text.index(f, pos)
        if k == i:
            return pos + 1
        pos += len(f)
    raise IndexError(i)


def test_parse_bodies_and_rods():
    deck = lines.parse_moordyn(lines.case_path("BodiesAndRods.dat"))
    assert deck.rod_types == {"Can": {"d": 10.0, "w": 1e3, "Cd": 0.6, "Ca": 1.0,
                                      "CdEnd": 1.2, "CaEnd": 1.0}}  # fmt: skip
    (b,) = deck.bodies
    assert (b["id"], b["kind"], b["position"], b["mass"]) == (1, "free", [0, 0, 0], 1e6)
    assert b["cg"] == [0, 0, 0] and b["inertia"] == [1e10] * 3 and b["volume"] == 0
    assert b["CdA"] == [0.0] * 6 and b["Ca"] == [0.0] * 3
    r1, r2 = deck.rods
    assert (r1["kind"], r1["body"], r1["end_a"], r1["end_b"], r1["segments"]) == (
        "fixed", 1, [0, 0, 2], [0, 0, 15], 3)  # fmt: skip
    assert (r2["kind"], r2["body"]) == ("pinned", 1)
    kinds = [(p["kind"], p["body"]) for p in deck.points]
    assert kinds[0] == ("body", 1) and kinds[1] == ("fixed", None)
    assert kinds[7] == ("free", None) and kinds[9] == ("body", 1)
    # MoorDyn reads the 10-column line types by position (headers are not parsed)
    assert deck.types["nylon"]["Cd"] == 1.0 and deck.types["nylon"]["CdAx"] == 1.6


def test_parse_body_columns():
    deck = lines.parse_moordyn(lines.case_path("body_tests/orbitalBody.txt"))
    assert [b["cg"] for b in deck.bodies] == [[0, -10, 0]] * 2
    assert deck.options["g"] == 0.0
    deck = lines.parse_moordyn(lines.case_path("body_tests/bodyDrag.txt"))
    (b,) = deck.bodies
    assert b["angles"] == [0.0, math.radians(-90.0), 0.0]
    assert b["CdA"] == [0.1] * 6 and b["inertia"] == [5.0] * 3
    deck = lines.parse_moordyn(lines.case_path("body_tests/pinnedBody.txt"))
    assert deck.bodies[0]["kind"] == "coupled_pinned" and deck.options["rho"] == 0
    # 11-column line type: Cl read (VIV is not modelled, but the deck's lines have
    # one segment each: no interior node feels it)
    deck = lines.parse_moordyn(lines.case_path("body_tests/rotatingBody.txt"))
    assert deck.types["nylon"]["Cl"] == 0.05
    assert [p["kind"] for p in deck.points][::4] == ["body", "fixed", "coupled"]


def test_parse_rod_ends_and_kinds():
    deck = lines.parse_moordyn(lines.case_path("RodHanging.txt"))
    assert [(ln["a"], ln["b"]) for ln in deck.lines] == [(1, (1, "A")), (2, (1, "B"))]
    assert deck.rods[0]["kind"] == "free"
    deck = lines.parse_moordyn(lines.case_path("RodPinnedFloating.txt"))
    assert [r["kind"] for r in deck.rods] == ["pinned", "pinned"] and not deck.lines
    deck = lines.parse_moordyn(lines.case_path("BeamCantilevered.txt"))
    assert deck.lines[0]["a"] == (1, "B") and deck.types["beam"]["EI"] == 1e7
    # the global position of a rod end and of a point on a rotated body
    assert list(lines.moordyn.end_position(deck, (1, "B"))) == [0.0, 0.0, 10.0]
    deck = lines.parse_moordyn(lines.case_path("body_tests/bodyDrag.txt"))
    deck.points[0]["position"] = [1.0, 0.0, 0.0]  # body x is global +z (pitch -90)
    np.testing.assert_allclose(
        lines.moordyn.end_position(deck, 1), [0, 0, 1], atol=1e-15
    )


@pytest.mark.parametrize(
    "deck, start, column, value, message",
    [
        # BODIES
        ("BodiesAndRods.dat", "1       free", 2, "Floating",
         r"column 2 \(Attachment\) 'Floating' is not a body attachment; valid: Free"),
        ("BodiesAndRods.dat", "1       free", 2, "Pinned",
         r"'Pinned' is not a body attachment"),
        ("BodiesAndRods.dat", "1       free", 9, "-1e6",
         r"column 9 \(Mass\) must be >= 0"),
        ("BodiesAndRods.dat", "1       free", 11, "1|2",
         r"column 11 \(I\) must hold 1 or 3 '\|'-separated numbers"),
        ("BodiesAndRods.dat", "1       free", 13, None,
         r"a body needs 14 columns \(ID Attachment X0"),
        # RODS
        ("BodiesAndRods.dat", "2      Can", 3, "Body2Pinned",
         r"body 2 is not in BODIES \(valid: 1..1\)"),
        ("BodiesAndRods.dat", "2      Can", 3, "Hinged",
         r"'Hinged' is not a rod attachment; valid: Fixed"),
        ("BodiesAndRods.dat", "2      Can", 10, "2.5",
         r"column 10 \(NumSegs\) must be an integer >= 0"),
        ("BodiesAndRods.dat", "2      Can", 2, "Pipe",
         r"rod type 'Pipe' is not in ROD TYPES"),
        ("RodHanging.txt", "1    rod", 7, "x",
         r"column 7 \(Xb\) must be a number"),
        ("RodHanging.txt", "1    rod", 9, None,
         r"a rod needs 10 columns"),
        # ROD TYPES, LINE TYPES (EI), LINES
        ("BodiesAndRods.dat", "Can ", 3, "-1",
         r"column 3 \(Mass/m\) must be >= 0"),
        ("BeamCantilevered.txt", "beam ", 6, "-1e7",
         r"column 6 \(EI\) must be >= 0"),
        ("BeamCantilevered.txt", "beam ", 6, "EI.dat",
         r"column 6 \(EI\) must be a number >= 0 \(N m\^2\)"),
        ("RodHanging.txt", "2     rope", 4, "R2B",
         r"rod 2 is not in RODS \(valid: 1..1\)"),
        ("RodHanging.txt", "2     rope", 4, "R1C",
         r"'R1C' is not a line end; valid: a point ID"),
    ],
)  # fmt: skip
def test_bad_rows_name_file_line_column(tmp_path, deck, start, column, value,
                                        message):  # fmt: skip
    """A bad value in a column (or a row cut short before it): the error names
    the file, the line, the character column of the field and the valid range."""
    rows = _rows(deck)
    k = _row(rows, start)
    fields = rows[k].split()
    fields = fields[: column - 1] if value is None else (
        fields[: column - 1] + [value] + fields[column:])  # fmt: skip
    rows[k] = "   ".join(fields)
    path = _write(tmp_path, rows)
    at = len(fields) - 1 if value is None else column - 1
    col = len("   ".join(fields[:at])) + (3 if at else 0) + 1
    with pytest.raises(ValueError, match=rf"{path}: line {k + 1}, column {col}: "
                       rf".*{message}"):  # fmt: skip
        lines.parse_moordyn(path)


def test_free_body_without_inertia(tmp_path):
    """A Free body with zero mass and zero volume is refused unless something
    with mass is on it (MoorDyn's orbitalBody: 20 kg points on a massless body)."""
    rows = _rows("body_tests/bodyDrag.txt")
    k = _row(rows, "1       free")
    rows[k] = rows[k].replace(" 1e1 ", " 0 ")
    lines.parse_moordyn(_write(tmp_path, rows))  # the line's end node carries mass
    j = _row(rows, "1         Body1")
    rows[j] = rows[j].replace("Body1", "Free ")
    path = _write(tmp_path, rows)
    col = _column(rows[k], 8)  # the Mass column
    message = "a Free body with zero Mass and zero Volume has no inertia"
    with pytest.raises(ValueError, match=rf"{path}: line {k + 1}, column {col}: "
                       + message):  # fmt: skip
        lines.parse_moordyn(path)
    lines.parse_moordyn(lines.case_path("body_tests/orbitalBody.txt"))


def test_cli_exits_2_on_a_bad_rod_row(tmp_path, capsys):
    rows = _rows("RodHanging.txt")
    k = _row(rows, "1    rod")
    rows[k] = rows[k].replace("Free", "Glued")
    deck = _write(tmp_path, rows)
    code = main(["run", "moordyn", deck, "--out", str(tmp_path / "out")])
    assert code == 2
    err = capsys.readouterr().err
    assert f"line {k + 1}, column" in err and "'Glued' is not a rod attachment" in err
