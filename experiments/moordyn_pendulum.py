"""The pendulum of MoorDyn's test suite, in MoorDyn and in jaxstring, side by side.

Question: on a mooring-style problem -- a 100.5 m line of 20 segments, EA = 1e9 N,
7.854 kg/m (neutrally buoyant: 0.1 m diameter in water of 1000 kg/m^3), an end mass
of 1e5 kg released from (10, -100) m, 40.2 s (two swings), 1 % segment damping --
how do MoorDyn (its explicit RK4 at the test suite's CFL 0.1) and jaxstring's
implicit solvers compare in wall time, and how far apart are their end-mass
trajectories?

Both start from the state that MoorDyn's own initial-condition solve produces (the
line stretched under the end mass); jaxstring uses the displacement formulation
with k = 20 (the same lumped-mass nodes), the segment damping that MoorDyn derives
(BA = zeta l_seg sqrt(EA w), alpha = BA/EA), a weightless line and the end weight
only. Accuracy is measured against jaxstring's own tight solve (rtol = 1e-10) and
against MoorDyn.

Run: ``python experiments/moordyn_pendulum.py [--quick]``. Needs the ``moordyn``
package (optional ``bench`` extra); without it only the jaxstring side runs.
"""

import importlib.util
import math
import os
import tempfile
from typing import ClassVar

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import jaxstring


LINE = {
    "l": 100.5,
    "segments": 20,
    "EA": 1e9,
    "w": 7.85398,
    "diam": 0.1,
    "zeta": 0.01,
    "m_point": 1e5,
    "x0": 10.0,
    "z0": -100.0,
    "t1": 40.2,
}
RHO_WATER = 1000.0
G = 9.81

INPUT = """--------------------- MoorDyn Input File ---------------------------------
Pendulum of MoorDyn's test suite (jaxstring experiments/moordyn_pendulum.py)
----------------------- LINE TYPES ------------------------------------------
TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx
(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)
main {diam} {w} {EA:.6E} -{zeta} 0 0.0 0.0 0.0 0.0
---------------------- POINT PROPERTIES -------------------------------------
ID Type X Y Z Mass Volume CdA Ca
(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)
1 Fixed 0 0 0 0 0 0 0
2 Free {x0} 0 {z0} {m_point:.6E} 0 0 0
---------------------- LINES ------------------------------------------------
ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs
(#) (name) (#) (#) (m) (-) (-)
1 main 1 2 {l} {segments} -
---------------------- OPTIONS ----------------------------------------------
0 writeLog Write a log file
{cfl} cfl CFL to determine the simulation timestep
RK4 tScheme The time integration Scheme (-)
{rho} WtrDnsty water density (kg/m^3)
500 WtrDpth water depth (m)
{dtIC} dtIC time interval for analyzing convergence during IC gen (s)
{TmaxIC} TmaxIC max time for ic gen (s)
1e-4 threshIC threshold for IC convergence (-)
0 ICgenDynamic IC generator (0 = stationary, 1 = legacy upscale dynamics)
------------------------- need this line ------------------------------------
"""


class EndWeight(jaxstring.AbstractStringLoad):
    """The weight of the end mass only: the line is neutrally buoyant in water.

    **Arguments:** `weight`: the end mass's weight, N (acting along -y).
    """

    weight: jnp.ndarray = eqx.field(converter=jnp.asarray)
    constant: ClassVar[bool] = True

    def forces(self, t, kin, env):
        del t, env
        dim = kin.positions.shape[-1]
        end = jnp.zeros((dim,)).at[1].set(-self.weight)
        return jaxstring.Loads(line=jnp.zeros_like(kin.positions), end=end)


def run_moordyn(ts, cfl=0.1, quick=False, workdir=None):
    """Run MoorDyn; return dict with init_s, run_s, end (T, 2) in (x, z), nodes0."""
    import moordyn

    workdir = workdir or tempfile.mkdtemp(prefix="jaxstring_moordyn_")
    path = os.path.join(workdir, "pendulum.txt")
    with open(path, "w") as f:
        f.write(
            INPUT.format(
                **LINE,
                cfl=cfl,
                rho=RHO_WATER,
                dtIC=0.5 if quick else 1.0,
                TmaxIC=20.0 if quick else 10000.0,
            )
        )
    with common.quiet_fd():
        system, init_s = common.moordyn_start(path)
        line = moordyn.GetLine(system, 1)
        nodes0 = np.array(
            [
                moordyn.GetLineNodePos(line, i)
                for i in range(moordyn.GetLineNumberNodes(line))
            ]
        )
        point = moordyn.GetPoint(system, 2)
        end = [np.asarray(moordyn.GetPointPos(point))]

        def steps():
            for a, b in zip(ts[:-1], ts[1:]):
                moordyn.Step(system, [], [], float(a), float(b - a))
                end.append(np.asarray(moordyn.GetPointPos(point)))

        _, run_s, _ = common.clock(steps)
        moordyn.Close(system)
    end = np.asarray(end)[:, [0, 2]]
    return {"init_s": init_s, "run_s": run_s, "end": end, "nodes0": nodes0[:, [0, 2]]}


def jaxstring_scene(nodes0, t1):
    """The same pendulum as a jaxstring scene (displacement variables, k = 20)."""
    k = LINE["segments"]
    h = LINE["l"] / k
    w, EA = LINE["w"], LINE["EA"]
    BA = LINE["zeta"] * h * math.sqrt(EA * w)  # MoorDyn's damping from -zeta
    # MoorDyn lumps half a segment's mass on the end node next to the point mass.
    m_s = LINE["m_point"] + 0.5 * w * h
    r = np.asarray(nodes0[1:], dtype=np.float64)
    y0 = np.concatenate([r, np.zeros_like(r)], axis=1)
    return jaxstring.string_pendulum(
        formulation="displacement",
        k=k,
        EA=EA,
        alpha=BA / EA,
        l=LINE["l"],
        mu=w,
        m_s=m_s,
        t1=t1,
        effects=(
            EndWeight(weight=LINE["m_point"] * G),
            jaxstring.KelvinVoigt(alpha=BA / EA),
        ),
        y0=jnp.asarray(y0),
    ), BA


def main(quick=False, solvers=None, tols=None, repeats=None, cfls=None):
    """Run the comparison; return the rows."""
    common.set_quick(quick)
    t1 = 4.0 if quick else LINE["t1"]
    ts = np.round(np.arange(0.0, t1 + 1e-9, 0.1), 10)
    repeats = repeats or (1 if quick else 3)
    tols = tols or ((1e-5,) if quick else (1e-4, 1e-6, 1e-8))
    cfls = cfls or ((0.1,) if quick else (0.1, 0.2))
    have_md = importlib.util.find_spec("moordyn") is not None
    md = {}
    if have_md:
        for cfl in cfls:
            try:
                runs = [
                    run_moordyn(ts, cfl, quick)
                    for _ in range(1 if quick else min(repeats, 2))
                ]
            except RuntimeError as e:  # MoorDyn's RK4 diverges above its CFL limit
                print(f"MoorDyn at cfl={cfl} failed: {e}")
                continue
            md[cfl] = runs[0]
            md[cfl]["run_s"] = float(np.median([r["run_s"] for r in runs]))
            md[cfl]["repeats"] = len(runs)
        nodes0 = md[cfls[0]]["nodes0"]
    else:
        print("moordyn is not installed: jaxstring side only")
        k = LINE["segments"]
        x0, z0 = LINE["x0"], LINE["z0"]
        nodes0 = np.linspace(0, 1, k + 1)[:, None] * np.array([[x0, z0]])
    scene, BA = jaxstring_scene(nodes0, t1)
    tight = jaxstring.simulate(
        scene,
        "kvaerno5",
        rtol=1e-10,
        atol=1e-10,
        ts=ts,
        max_steps=common.MAX_STEPS if quick else 1_000_000,
    )
    ref = np.asarray(tight.end_mass)
    md_ref = md[cfls[0]]["end"] if have_md else None
    rows = []
    for cfl, r in md.items():
        rows.append(
            {
                "code": f"MoorDyn RK4 cfl={cfl}",
                "ok": bool(np.all(np.isfinite(r["end"]))),
                "setup_s": r["init_s"],
                "run_s": r["run_s"],
                "repeats": r["repeats"],
                "err_vs_tight_m": common.end_mass_error(r["end"], ref),
                "diff_vs_moordyn_m": common.end_mass_error(r["end"], md_ref),
                "x_end_m": r["end"][-1, 0],
            }
        )
    names = solvers or ["kvaerno5", "bdf"] + [n for n in ("rodas5p",) if not quick]
    for name in names:
        if name not in jaxstring.SOLVERS or not jaxstring.SOLVERS[name][1]:
            continue
        for tol in tols:
            r = common.run_jaxstring(
                scene, name, ts, rtol=tol, atol=tol, repeats=repeats
            )
            end = r.pop("end")
            rows.append(
                {
                    "code": f"jaxstring {name} rtol={tol:g}",
                    "ok": r["ok"],
                    "setup_s": r["compile_s"],
                    "run_s": r["run_s"],
                    "repeats": r["repeats"],
                    "steps": r.get("num_steps"),
                    "err_vs_tight_m": common.end_mass_error(end, ref)
                    if r["ok"]
                    else math.nan,
                    "diff_vs_moordyn_m": common.end_mass_error(end, md_ref)
                    if (r["ok"] and have_md)
                    else math.nan,
                    "x_end_m": float(end[-1, 0]) if r["ok"] else math.nan,
                }
            )
            print(rows[-1], flush=True)
            if not r["ok"] or r["run_s"] > 120.0:
                break  # tighter tolerances would only cost more
    tag = "_quick" if quick else ""
    common.write_table(
        f"moordyn_pendulum{tag}",
        rows,
        (
            "code ok setup_s run_s repeats steps err_vs_tight_m diff_vs_moordyn_m "
            "x_end_m"
        ).split(),
        f"MoorDyn test-suite pendulum: {LINE['l']} m, {LINE['segments']} segments, "
        f"EA={LINE['EA']:g} N, {LINE['w']} kg/m, end mass {LINE['m_point']:g} kg, "
        f"{t1} s",
        notes=[
            "setup_s: MoorDyn's initial-condition solve (Create + Init) or jaxstring's"
            " compile (first call minus median); run_s: the time stepping only.",
            f"err_vs_tight_m: max end-mass distance (m, {len(ts)} times, every 0.1 s) "
            "to jaxstring kvaerno5 at rtol=atol=1e-10 on the same jaxstring model; "
            "diff_vs_moordyn_m: to MoorDyn at the first cfl.",
            f"jaxstring model: displacement, k={LINE['segments']}, alpha = BA/EA with "
            f"BA = {BA:.1f} N s (MoorDyn's value from zeta = {LINE['zeta']}), "
            "weightless line, end weight 1e5 g, end-node mass 1e5 + half a segment.",
            "initial state: MoorDyn's node positions after its IC solve, at rest.",
        ],
    )
    fig, axes = common.new_figure(2, 1, w=5.5)
    ax, ax2 = axes[0]
    if have_md:
        for cfl, r in md.items():
            ax.plot(ts, r["end"][:, 0], label=f"MoorDyn cfl={cfl}")
            ax2.semilogy(
                ts,
                np.linalg.norm(r["end"] - ref, axis=1) + 1e-16,
                label=f"MoorDyn cfl={cfl}",
            )
    ax.plot(ts, ref[:, 0], "--", label="jaxstring kvaerno5 1e-10")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("end mass x (m)")
    ax.legend(fontsize=7)
    ax2.set_xlabel("t (s)")
    ax2.set_ylabel("|MoorDyn - jaxstring| (m)")
    ax2.legend(fontsize=7)
    common.savefig(fig, f"moordyn_pendulum{tag}")
    return rows


if __name__ == "__main__":
    common.run_study(main)
