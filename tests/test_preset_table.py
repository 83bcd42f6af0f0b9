"""The accuracy presets are read from the machine-readable table
(jaxstring/presets.json) that experiments/race_strongest.py --presets writes, with a
stamp naming where they were measured."""

from jaxstring._presets import ACCURACY_PRESETS, preset_sources


def test_presets_are_the_measured_table():
    # The choices the presets study made (experiments/results/race_strongest_
    # presets.md): BDF in displacement variables, Rodas5P elsewhere.
    assert ACCURACY_PRESETS["balanced"]["displacement"]["solver"] == "bdf"
    assert ACCURACY_PRESETS["balanced"]["displacement"]["rtol"] == 1e-7
    for system in ("natural", "angle", "tether", "other"):
        assert ACCURACY_PRESETS["precise"][system]["solver"] == "rodas5p"


def test_table_names_its_measurement():
    sources = preset_sources()
    for system in ("displacement", "natural", "angle", "tether"):
        assert sources[system]["results"] == (
            "experiments/results/race_strongest_presets.md"
        )
    assert sources["other"]["results"].endswith("race_strongest_presets_tandem.md")
    assert all("date: " in sources[s]["stamp"] for s in sources if s != "table")
    assert {"date", "machine", "commit", "command"} <= set(sources["table"])
