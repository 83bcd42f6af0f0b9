"""The analytic catenary and MoorDyn's lumped-mass model agree as the segments
shrink: the OC3-Hywind deck (lines.txt, fairleads held) at N = 20, 40, 80
segments per line (`static_tensions` of the lumped-mass statics) against the
catenary system's tensions (`mooring_equilibrium`), the same g (MoorDyn's
9.80665): the largest relative difference of the fairlead and anchor tensions
falls from 1.4e-3 to 8e-5, at second order in the segment length (a fitted slope
of -2 +- 0.2 in log-log), so the two models converge to one answer.
"""

import copy

import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring import lines


@pytest.mark.slow
def test_lumped_mass_converges_to_the_catenary():
    deck = lines.parse_moordyn(lines.case_path("lines.txt"))
    out = lines.mooring_equilibrium(lines.mooring_system(deck))
    T = np.asarray(out.tension)  # (3 lines, (anchor, fairlead))
    Ns, diffs = (20, 40, 80), []
    for N in Ns:
        d = copy.deepcopy(deck)
        for ln in d.lines:
            ln["segments"] = N
        st = lines.static_tensions(lines.deck_scene(d))
        lumped = np.array([st[ln["id"]] for ln in deck.lines])
        diffs.append(np.max(np.abs(lumped - T) / T))
    print(dict(zip(Ns, diffs)))
    assert diffs[0] < 2e-3 and diffs[-1] < 1e-4
    assert diffs[0] > diffs[1] > diffs[2]
    slope = np.polyfit(np.log(Ns), np.log(diffs), 1)[0]
    assert -2.2 < slope < -1.8, slope
