"""The accuracy presets' machine-readable table (jaxstring/_solvers/presets.json,
written by experiments/race_strongest.py --presets) holds the presets that
jaxstring/_solvers/presets.py types out, with a stamp naming where they were
measured."""

from jaxstring._solvers.preset_table import (
    load_presets,
    preset_sources,
    preset_targets,
)
from jaxstring._solvers.presets import ACCURACY_PRESETS, PRESET_TARGETS


def test_table_equals_the_presets():
    assert load_presets() == ACCURACY_PRESETS
    assert preset_targets() == PRESET_TARGETS


def test_table_names_its_measurement():
    sources = preset_sources()
    for system in ("displacement", "natural", "angle", "tether"):
        assert sources[system]["results"] == (
            "experiments/results/race_strongest_presets.md"
        )
    assert sources["other"]["results"].endswith("race_strongest_presets_tandem.md")
    assert all("date: " in sources[s]["stamp"] for s in sources if s != "table")
    assert {"date", "machine", "commit", "command"} <= set(sources["table"])
