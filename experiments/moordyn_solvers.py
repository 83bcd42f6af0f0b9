"""Every solver on every MoorDyn deck: does each run finish, and how?

Question: do jaxstring's solvers integrate each of MoorDyn's test decks (lines,
points, bodies, rods, bending, a line paid in from slack, a free spar through the
surface) from the deck's own start (`static=False`: MoorDyn's straight initial
lines, no static solve) without NaN, step-size collapse or a failed Newton
iteration? Each deck runs a short horizon with Kvaerno5 (the default), BDF,
Rodas5P, implicit Euler and Tsit5 at rtol = atol = 1e-3 and a step cap of 4000;
reported per run: its status, how far it got, accepted and rejected steps,
whether every saved state is finite, and the first call (compilation included)
and a second call's wall time.

A run that stops at the step cap with accepted steps far above rejected ones is
resolving a stiff, lightly damped oscillation (a slack line snapping taut, a
beam's bending modes, a float's), not collapsing: more steps finish it.

Run: ``python experiments/moordyn_solvers.py [--quick]``. Writes
results/moordyn_solvers.{md,csv}.
"""

import os
import tempfile

import _common as common
import numpy as np

import jaxstring as js
from jaxstring import lines


SOLVERS = ("kvaerno5", "bdf", "rodas5p", "implicit_euler", "tsit5")
RTOL = 1e-3
MAX_STEPS = 4000

SPAR = """\
--------------------- MoorDyn Input File ---------------------------------------
A free spar (a rod 1 m across, 9 m long, 400 kg/m) through the surface, tilted
6 deg, moored to the seabed by one chain on its lower end
---------------------- LINE TYPES ------------------------------------------------
TypeName   Diam     Mass/m     EA     BA/-zeta    EI    Cd     Ca    CdAx    CaAx
(name)     (m)      (kg/m)     (N)    (N-s/-)   (N-m^2) (-)    (-)   (-)     (-)
chain      0.05     20.0       1e8    -0.8      0       1.2    1.0   0.2     0.0
---------------------- ROD TYPES -----------------------------------------------
TypeName      Diam     Mass/m    Cd     Ca      CdEnd    CaEnd
(name)        (m)      (kg/m)    (-)    (-)     (-)      (-)
spar          1.0      400.0     0.8    1.0     0.6      0.6
---------------------- RODS ----------------------------------------------------
ID   RodType   Attachment  Xa    Ya    Za    Xb    Yb    Zb   NumSegs  RodOutputs
(#)  (name)     (#/key)    (m)   (m)   (m)   (m)   (m)   (m)  (-)       (-)
1    spar      Free        0     0     -6.0  1.0   0     3.0  8         p
---------------------- POINTS ----------------------------------------------------
ID   Attachment  X       Y     Z      Mass  Volume  CdA   Ca
(#)  (-)         (m)     (m)   (m)    (kg)  (m^3)   (m^2) (-)
1    Fixed       40      0     -30    0     0       0     0
---------------------- LINES -----------------------------------------------------
ID   LineType  AttachA  AttachB  UnstrLen  NumSegs  LineOutputs
(#)  (name)    (#)      (#)      (m)       (-)      (-)
1    chain     1        R1A      48.0      10       p
---------------------- OPTIONS -------------------------------------------------
1e-4          dtM                  time step to use in mooring integration (s)
1000          WtrDnsty             water density (kg/m^3)
30            WtrDpth              water depth (m)
0.0           TmaxIC               max time for ic gen (s)
------------------------- need this line ---------------------------------------
"""

# (deck, horizon s): MoorDyn's decks, then the spar above
DECKS = (
    ("BodiesAndRods.dat", 1.0),
    ("RodHanging.txt", 3.0),
    ("RodPinnedFloating.txt", 2.0),
    ("rod_tests/AddedMass.txt", 1.0),
    ("body_tests/bodyDrag.txt", 2.0),
    ("body_tests/orbitalBody.txt", 2.0),
    ("body_tests/pinnedBody.txt", 2.0),
    ("body_tests/rotatingBody.txt", 2.0),
    ("tripod.txt", 0.5),
    ("lifting.txt", 2.0),
    ("lines.txt", 2.0),
    ("pendulum.txt", 2.0),
    ("BeamCantilevered.txt", 0.5),
    ("WD0050_Chain.txt", 5.0),
    ("spar", 5.0),
)


def run(scene, solver):
    """One run: its row (status, reach, steps, finite states, timings)."""
    call = lambda: js.simulate(
        scene, solver, rtol=RTOL, atol=RTOL, n_save=5, max_steps=MAX_STEPS
    )
    traj, first, _ = common.clock(lambda: common.block(call()))
    _, second, _ = common.clock(lambda: common.block(call()))
    n = int(traj.n_valid)
    return {
        "solver": solver,
        "ok": bool(traj.ok),
        "status": "" if traj.ok else traj.status.split(".")[0],
        "t_end": float(traj.t_end),
        "accepted": int(traj.stats["num_accepted_steps"]),
        "rejected": int(traj.stats["num_rejected_steps"]),
        "finite": bool(np.all(np.isfinite(np.asarray(traj.ys)[:n]))),
        "first_s": first,
        "run_s": second,
    }


def main(quick=False):
    common.set_quick(quick)
    js.disable_compilation_cache()  # each first call compiles
    decks = DECKS[1:3] if quick else DECKS
    solvers = SOLVERS[:2] if quick else SOLVERS
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        spar = os.path.join(folder, "spar.txt")
        with open(spar, "w") as f:
            f.write(SPAR)
        for name, t1 in decks:
            path = spar if name == "spar" else lines.case_path(name)
            scene = lines.read_moordyn(path, static=False, t1=t1)
            for solver in solvers:
                row = {"deck": name.split("/")[-1], "t1": t1} | run(scene, solver)
                print(row, flush=True)
                rows.append(row)
    columns = (
        "deck t1 solver ok status t_end accepted rejected finite first_s run_s"
    ).split()
    common.write_table(
        "moordyn_solvers",
        rows,
        columns,
        "Every solver on every MoorDyn deck (rtol = atol = 1e-3, at most 4000 steps)",
        notes=[
            "Each deck from its own start (`static=False`), t1 its horizon (s); "
            "spar: a free rod through the surface moored by a chain (in the "
            "script). ok False: the run stopped at t_end (status: why); finite: "
            "every saved state finite up to there.",
            "first_s: the first call, compilation included (no compilation "
            "cache); run_s: a second call. The machine has 2 cores and is shared.",
        ],
    )
    return rows


if __name__ == "__main__":
    common.run_study(main)
