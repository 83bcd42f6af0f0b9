"""Blintsov's (2017) tether in MoorDyn and in jaxstring, side by side.

Question: on the paper's fixed-length scenario (``tether_fixed``: 100 m cable,
N = 101, d = 10 mm, rho = 1024 kg/m^3, neutral buoyancy, c_n = 1, c_t = 0.1, uniform
current (-1, 0, 0) m/s, root fixed at the origin, running end from (0, 0, -50) m:
0-10 s still, 10-35 s rising at 1 m/s, 35-45 s still, 45-70 s moving +x at 1 m/s),
how do MoorDyn-C (lumped masses, a very stiff axial spring, explicit RK4) and
jaxstring's inextensible tethers (``ExactTether``, ``AceamTether``; Dormand-Prince,
rtol = atol = 1e-6) compare in wall time, end forces, shape and length error?

MoorDyn set-up (v2 input file, written by ``moordyn_input``):

- one line of `segments` segments (default 102: the same link length L/(N + 1) as
  jaxstring's chain, whose N = 101 elements then coincide with MoorDyn's 101 free
  nodes; the brief's 100 segments is run too in the full mode) between two
  *Coupled* points: the root, held at the origin, and the running end, whose
  position and velocity are prescribed at every coupling step (`moordyn.Step`);
  the forces that Step returns are the forces of the line on the two points, the
  same quantity as jaxstring's ``root_force`` / ``fast_force``;
- EA = 1e7 N (a 10 mm steel wire rope has about 1.6e7 N): the end forces of the
  scenario stay below about 160 N away from the velocity jumps (spikes of a few
  hundred N at the jumps), a strain below 2e-5, far below the paper's length
  error (3e-4) and ACEAM's; EA = 1e8 N is run in the full mode to show that the
  forces no longer depend on EA (the inextensible limit). Internal damping
  BA/-zeta = -1 (critical for the segment axial mode);
- time step: MoorDyn derives dtM from its CFL option (the segment's axial natural
  period, computed without added mass); RK4 diverged at CFL 0.35 while the line
  settles and at CFL 0.25 at the first velocity jump of the running end (t = 10 s),
  so CFL = 0.2 is used (dtM = 1.10e-4 s at EA = 1e7 N; dtM ~ 1/sqrt(EA)); the table
  reports dtM;
- current: the MoorDyn-C option ``Currents 1`` (steady depth profile read from
  ``current_profile.txt`` next to the input file; here (-1, 0, 0) m/s at every
  depth). ``WaterKin`` is the MoorDyn-F (OpenFAST) option and is not read by
  MoorDyn-C 2.7.2. Note that MoorDyn's initial-condition solver ignores currents
  (its log: "Water kinematics for IC gen: No Waves or Currents"), see below;
- hydrodynamics (``line_properties``, read from the scene): MoorDyn's Cd acts on
  the frontal area d l and CdAx on the surface pi d l, exactly as jaxstring's
  `Drag` (D_n = d l_e, D_t = pi d l_e), so Cd = Drag.Cd = 1 and CdAx = Drag.CdAx.
  ``tether_fixed`` reads the paper's c_t = 0.1 as a coefficient on the projected
  area d l_e (see its docstring) and hands `Drag` c_t/pi = 0.0318, so MoorDyn gets
  CdAx = 0.0318, not 0.1 (with 0.1 MoorDyn's end forces at 10 s are 40 % higher).
  Checked numerically by ``check_axial_drag``: a straight line in an axial current
  gets 0.5 rho CdAx pi d l u^2 per node.
  Added mass Ca = CaAx = 1: jaxstring's element inertia mu = m + C_a rho Q is
  isotropic, so the axial added mass is 1 as well;
- weight: mass per metre rho pi d^2/4, so weight and buoyancy cancel in both codes;
- the whole scene is shifted down by 500 m in MoorDyn (water depth 2000 m), so that
  no node comes near MoorDyn's free surface or seabed (jaxstring has neither;
  jaxstring's initial arc rises 0.3 m above the root). Positions are shifted
  back before comparing.

Initial state: the same in both. jaxstring's scene starts from an arc of the full
length at rest (``arc_state``); MoorDyn is initialised without its IC solve
(``Init_NoIC``) and its state is then set to the same node positions at rest
(``SaveState``, the line block replaced, ``LoadState``; the file layout is the one
``moordyn.moorpy_export`` writes). Both settle during 0-10 s.

Comparison (all in the same process): wall and CPU time of the time stepping
(jaxstring compile reported apart, median of repeats), end forces every 0.05 s
(max relative difference |F_js - F_md| / |F_md| after 10 s, with and without 1 s
after each kink of the schedule, where the velocity jumps and both codes spike),
node distance at 10, 35, 45 and 70 s, and the length error (L - sum of segment
lengths)/L. The full mode adds a diagnostic jaxstring run, ``exact-central``: the
exact tether with the drag taken on MoorDyn's element tangent
(``CentralTangentDrag``), which isolates the one modelling difference that shows.

Run: ``python experiments/tether_moordyn.py [--quick]`` (quick: 11 s of the
scenario, one repeat, the primary MoorDyn set-up only). Writes
``results/tether_moordyn.{md,csv,png}``.
"""

import os


os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import importlib.util
import math
import statistics
import struct
import tempfile

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from _common import new_figure, savefig, set_quick, write_table

import jaxstring as js
from jaxstring.tether.scenes import tether_fixed


# The scenario (paper Table 1); passed explicitly to tether_fixed and to MoorDyn.
PARAMS = {
    "L": 100.0,
    "N": 101,
    "d": 0.01,
    "rho": 1024.0,
    "c_n": 1.0,
    "c_t": 0.1,
    "g": 9.81,
    "added_mass": 1.0,
    "current": (-1.0, 0.0, 0.0),
}
# Where the running end's velocity jumps (at 70 s jaxstring's schedule stops: its
# velocity is 0 from the last knot on, while MoorDyn's last step ends there).
KNOTS = (10.0, 35.0, 45.0, 70.0)
DEPTH_SHIFT = -500.0  # MoorDyn scene lies 500 m deeper (no surface, no seabed)
DT_OUT = 0.05  # comparison interval, s (also jaxstring's save interval)
SHAPE_TIMES = (10.0, 35.0, 45.0, 70.0)
RTOL = 1e-6
CFL = 0.2  # MoorDyn RK4: 0.25 diverges at the first velocity jump (t = 10 s)

INPUT = """--------------------- MoorDyn Input File ---------------------------------
Blintsov (2017) tether, fixed length (jaxstring experiments/tether_moordyn.py)
----------------------- LINE TYPES ------------------------------------------
TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx
(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)
cable {d!r} {w!r} {EA:.6E} {zeta} 0 {c_n!r} {Ca!r} {c_t!r} {Ca!r}
---------------------- POINTS -------------------------------------
ID Attachment X Y Z Mass Volume CdA Ca
(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)
1 Coupled {ra[0]!r} {ra[1]!r} {ra[2]!r} 0 0 0 0
2 Coupled {rb[0]!r} {rb[1]!r} {rb[2]!r} 0 0 0 0
---------------------- LINES ------------------------------------------------
ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs
(#) (name) (#) (#) (m) (-) (-)
1 cable 1 2 {L!r} {segments} -
---------------------- OPTIONS ----------------------------------------------
0 writeLog Write a log file
1 disableOutput no console output
1 disableOutTime no time stamps on the console
{cfl} CFL Courant number that sets dtM
RK4 tScheme time integrator
{g!r} g gravity (m/s^2)
{rho!r} rho water density (kg/m^3)
{depth} WtrDpth water depth (m)
1 Currents steady current profile from current_profile.txt
------------------------- need this line ------------------------------------
"""

CURRENT = """--------------------- MoorDyn steady currents File ------------------------
uniform current of jaxstring experiments/tether_moordyn.py
z (m), ux (m/s), uy (m/s), uz (m/s)
{zlo} {u[0]!r} {u[1]!r} {u[2]!r}
0.0 {u[0]!r} {u[1]!r} {u[2]!r}
"""


def line_properties(scene):
    """MoorDyn line and environment parameters read from a jaxstring tether scene.

    jaxstring's `Drag` puts the tangential coefficient on the wetted area pi d l_e
    and the normal one on d l_e, exactly as MoorDyn's CdAx and Cd, so CdAx is the
    scene's `Drag.CdAx` as it is (``tether_fixed`` may have converted the paper's
    c_t to that area first) and Cd its `c_n`. The element inertia is isotropic,
    so Ca = CaAx = `added_mass`."""
    model = scene.model
    drag = [e for e in scene.effects if isinstance(e, js.Drag)]
    if len(drag) != 1 or scene.env.current is None:
        raise ValueError("`scene` must have one Drag effect and a current.")
    drag = drag[0]
    if drag.Cl is not None and float(drag.Cl) != 0.0:
        raise ValueError("`scene`: MoorDyn has no lateral drag; Cl must be None or 0.")
    return {
        "L": float(model.L),
        "d": float(model.d),
        "w": float(model.mass_per_length),
        "rho": float(scene.env.rho_water),
        "Ca": float(model.added_mass),
        "Cd": float(drag.Cd),
        "CdAx": float(drag.CdAx),
        "current": tuple(float(u) for u in np.asarray(scene.env.current.velocity)),
        "g": PARAMS["g"],
    }


def moordyn_input(workdir, props, segments, EA, cfl=CFL, zeta=-1.0, ra=None, rb=None):
    """Write the MoorDyn input and current files for `props` (`line_properties`);
    return the input path."""
    ra = (0.0, 0.0, DEPTH_SHIFT) if ra is None else ra
    rb = (0.0, 0.0, DEPTH_SHIFT - 50.0) if rb is None else rb
    depth = 4 * abs(DEPTH_SHIFT)
    path = os.path.join(workdir, "tether.txt")
    with open(path, "w") as f:
        f.write(
            INPUT.format(
                d=props["d"],
                w=props["w"],
                EA=EA,
                zeta=zeta,
                c_n=props["Cd"],
                c_t=props["CdAx"],
                Ca=props["Ca"],
                ra=ra,
                rb=rb,
                L=props["L"],
                segments=segments,
                cfl=cfl,
                g=props["g"],
                rho=props["rho"],
                depth=depth,
            )
        )
    with open(os.path.join(workdir, "current_profile.txt"), "w") as f:
        f.write(CURRENT.format(zlo=-float(depth), u=props["current"]))
    return path


def _set_line_state(system, workdir, nodes):
    """Put the line's free nodes at `nodes` (n, 3), at rest, via Save/LoadState.

    The state file is MoorDyn's own (``SaveState`` after ``Init_NoIC``): b'MoorDyn',
    two version bytes, the number of 8-byte words, the number of blocks, then per
    block (rows, columns, rows x columns doubles); the line's block has one row
    (position, velocity) per free node (the layout ``moordyn.moorpy_export``
    writes)."""
    import moordyn

    src = os.path.join(workdir, "state0.bin")
    dst = os.path.join(workdir, "state1.bin")
    moordyn.SaveState(system, src)
    with open(src, "rb") as f:
        buf = bytearray(f.read())
    off = 9 + 16
    found = False
    while off < len(buf):
        rows, cols = struct.unpack_from("<QQ", buf, off)
        off += 16
        if rows == len(nodes) and cols == 6:
            state = np.zeros((rows, 6))
            state[:, :3] = nodes
            buf[off : off + 8 * rows * cols] = state.astype("<f8").tobytes()
            found = True
        off += 8 * rows * cols
    if not found:
        raise RuntimeError("MoorDyn state file: no block for the line's free nodes")
    with open(dst, "wb") as f:
        f.write(bytes(buf))
    moordyn.LoadState(system, dst)


def _get_dt(system):
    """MoorDyn's time step dtM, s. (The Python wrapper's ``moordyn.GetDt`` of
    2.7.2 drops the return value, so the C extension is called directly.)"""
    try:
        import cmoordyn

        return float(cmoordyn.get_dt(system))
    except Exception:  # an other wrapper layout: report nan, not fail
        return math.nan


def resample_chain(points, n):
    """Points of a chain of equal nominal links resampled to `n` equal links, by
    the fraction of the chain's index (both codes split the cable into equal
    unstretched segments), (n + 1, 3)."""
    points = np.asarray(points)
    s_old = np.linspace(0.0, 1.0, len(points))
    s_new = np.linspace(0.0, 1.0, n + 1)
    return np.stack([np.interp(s_new, s_old, points[:, i]) for i in range(3)], 1)


def check_axial_drag(workdir, props, segments=102, EA=1e7, cfl=CFL):
    """MoorDyn's axial drag on a straight line in an axial 1 m/s current, per
    node, divided by 0.5 rho CdAx (pi d l) (1 if CdAx is on the pi d l area)."""
    import moordyn

    p = props
    ra = (0.0, 0.0, DEPTH_SHIFT)
    rb = (p["L"], 0.0, DEPTH_SHIFT)  # straight along x: the current is axial
    path = moordyn_input(workdir, p, segments, EA, cfl, ra=ra, rb=rb)
    x = [*ra, *rb]
    with common.quiet_fd():
        system = moordyn.Create(path)
        moordyn.Init_NoIC(system, x, [0.0] * 6)
        moordyn.Step(system, x, [0.0] * 6, 0.0, 1e-6)
        line = moordyn.GetLine(system, 1)
        drag = np.asarray(moordyn.GetLineNodeDrag(line, segments // 2))
        moordyn.Close(system)
    l_seg = p["L"] / segments
    speed = abs(p["current"][0])
    area = math.pi * p["d"] * l_seg
    return float(-drag[0] / (0.5 * p["rho"] * p["CdAx"] * area * speed**2))


def run_moordyn(scene, nodes0, t_out, segments, EA, cfl=CFL, workdir=None):
    """Run the scenario of the jaxstring tether `scene` in MoorDyn.

    `nodes0`: initial chain (mounts included, scene coordinates); the running end
    follows the scene's `PrescribedEnd` (its `kinematics(t)`); `t_out`: comparison
    times (multiples of the coupling step).

    Returns a dict: setup_s (Create + Init_NoIC + LoadState), run_s and cpu_s (the
    Step calls only), dtM, root/fast forces (T, 3), nodes (T, segments + 1, 3).
    """
    import moordyn

    workdir = workdir or tempfile.mkdtemp(prefix="jaxstring_tether_md_")
    props = line_properties(scene)
    fast = scene.model.fast
    path = moordyn_input(workdir, props, segments, EA, cfl)
    shift = np.array([0.0, 0.0, DEPTH_SHIFT])
    interior = resample_chain(nodes0, segments)[1:-1] + shift

    def ends(t):
        k = fast.kinematics(t)
        return np.asarray(k.position) + shift

    root = np.array([0.0, 0.0, DEPTH_SHIFT])
    dtc = float(t_out[1] - t_out[0])
    with common.quiet_fd():

        def setup():
            system = moordyn.Create(path)
            moordyn.Init_NoIC(system, [*root, *ends(t_out[0])], [0.0] * 6)
            _set_line_state(system, workdir, interior)
            return system

        system, setup_s, _ = common.clock(setup)
        dtM = _get_dt(system)
        line = moordyn.GetLine(system, 1)
        pt_fast = moordyn.GetPoint(system, 2)
        F_root, F_fast, nodes = [], [], []
        wall = cpu = 0.0

        def record(f):
            F_root.append(f[:3])
            F_fast.append(f[3:])
            nodes.append([moordyn.GetLineNodePos(line, i) for i in range(segments + 1)])

        f0 = None
        for a in t_out[:-1]:
            xa, xb = ends(a), ends(a + dtc)
            va = (xb - xa) / dtc  # exact: the schedule is linear over each step
            f, w, c = common.clock(
                lambda: moordyn.Step(system, [*root, *xa], [0.0, 0.0, 0.0, *va], a, dtc)
            )
            wall += w
            cpu += c
            if f0 is None:  # forces at t_out[0] are not returned; repeat the first
                f0 = f
                record(f)
            record(f)
        end_err = np.linalg.norm(np.asarray(moordyn.GetPointPos(pt_fast)) - xb)
        moordyn.Close(system)
    if end_err > 1e-9:
        raise RuntimeError(f"MoorDyn's running end is {end_err} m off the schedule")
    nodes = np.asarray(nodes) - shift
    l = np.linalg.norm(np.diff(nodes, axis=1), axis=2).sum(axis=1)
    L = props["L"]
    return {
        "setup_s": setup_s,
        "run_s": wall,
        "cpu_s": cpu,
        "dtM": dtM,
        "root_force": np.asarray(F_root),
        "fast_force": np.asarray(F_fast),
        "nodes": nodes,
        "length_error": (L - l) / L,
    }


class CentralTangentDrag(js.AbstractChainLoad):
    """Diagnostic: the scene's `Drag` with MoorDyn's element tangent.

    jaxstring's tether hands its loads the direction of the link *ahead* of each
    element; MoorDyn uses the direction between the two neighbours. This wrapper
    passes the normalised sum of the links on both sides (the root link from the
    fixed root at the origin), to show what the choice does to the end forces.
    """

    drag: js.Drag

    def forces(self, t, kin, env):
        ahead = kin.tangents
        root_link = kin.positions[0] / jnp.linalg.norm(kin.positions[0])
        behind = jnp.concatenate([root_link[None], ahead[:-1]], axis=0)
        both = ahead + behind
        both = both / jnp.linalg.norm(both, axis=1, keepdims=True)
        kin = eqx.tree_at(lambda k: k.tangents, kin, both)
        return self.drag.forces(t, kin, env)


def jaxstring_scene(method, t1):
    """`tether_fixed` for `method` ("exact", "aceam", or "exact-central": the
    exact tether with `CentralTangentDrag`)."""
    base, _, variant = method.partition("-")
    scene = tether_fixed(base, **PARAMS, t1=t1)
    if variant == "central":
        effects = tuple(
            CentralTangentDrag(e) if isinstance(e, js.Drag) else e
            for e in scene.effects
        )
        scene = js.Scene(
            model=scene.model,
            effects=effects,
            y0=scene.y0,
            t1=t1,
            name=method,
            env=scene.env,
        )
    return scene


def run_jaxstring(method, ts, repeats):
    """Compile, then time `repeats` dopri5 runs; return a dict like run_moordyn's."""
    scene = jaxstring_scene(method, float(ts[-1]))

    traj, compile_s, run, cpu = common.timed_wall_cpu(
        lambda: js.simulate(
            scene, "dopri5", rtol=RTOL, atol=RTOL, ts=ts, max_steps=2_000_000
        ),
        repeats,
    )
    return {
        "scene": scene,
        **common.timing_fields(traj, compile_s, run, cpu),
        "repeats": repeats,
        "root_force": np.asarray(traj.root_force),
        "fast_force": np.asarray(traj.fast_force),
        "nodes": np.asarray(traj.nodes),
        "length_error": np.asarray(traj.length_error),
    }


def force_difference(ts, F, F_ref, t_from=10.0, skip=0.0, stat=np.max):
    """`stat` (max) over t > t_from of |F - F_ref| / |F_ref|, leaving out `skip`
    seconds after each kink of the schedule."""
    sel = ts > t_from + 1e-9
    for k in KNOTS:
        sel &= ~((ts > k - 1e-9) & (ts < k + skip))
    if not np.any(sel):
        return math.nan
    d = np.linalg.norm(F[sel] - F_ref[sel], axis=1)
    return float(stat(d / np.linalg.norm(F_ref[sel], axis=1)))


def shape_distance(nodes, nodes_ref):
    """Max distance between two chains at matched index fraction, m."""
    n = len(nodes_ref) - 1
    return float(np.max(np.linalg.norm(resample_chain(nodes, n) - nodes_ref, axis=1)))


def settled_force(ts, F, t=10.0, window=0.5):
    """Mean end force over the last `window` s before `t` (end of the settle phase)."""
    sel = (ts > t - window - 1e-9) & (ts < t - 1e-9)
    return F[sel].mean(axis=0)


def main(quick=False, methods=None, repeats=None, variants=None):
    """Run the comparison; return (rows, data)."""
    set_quick(quick)
    t1 = 11.0 if quick else 70.0
    ts = np.round(np.arange(0.0, t1 + 1e-9, DT_OUT), 10)
    repeats = repeats or (1 if quick else 3)
    if methods is None:
        methods = ("exact", "aceam") if quick else ("exact", "aceam", "exact-central")
    have_md = importlib.util.find_spec("moordyn") is not None
    runs = {}
    for m in methods:
        runs[m] = run_jaxstring(m, ts, repeats)
        print(f"jaxstring {m}: run {runs[m]['run_s']:.3f} s", flush=True)
    scene = runs[methods[0]]["scene"]
    nodes0 = runs[methods[0]]["nodes"][0]
    md = {}
    drag_ratio = math.nan
    props = line_properties(scene)
    if have_md:
        drag_ratio = check_axial_drag(tempfile.mkdtemp(prefix="jaxstring_drag_"), props)
        if variants is None:
            variants = [(102, 1e7)] if quick else [(102, 1e7), (100, 1e7), (102, 1e8)]
        for segments, EA in variants:
            key = f"MoorDyn S={segments} EA={EA:g}"
            n_rep = 1 if (quick or (segments, EA) != variants[0]) else 2
            reps = [run_moordyn(scene, nodes0, ts, segments, EA) for _ in range(n_rep)]
            md[key] = reps[-1]
            md[key]["run_s"] = statistics.median([r["run_s"] for r in reps])
            md[key]["cpu_s"] = statistics.median([r["cpu_s"] for r in reps])
            md[key]["repeats"] = n_rep
            md[key]["segments"], md[key]["EA"] = segments, EA
            print(f"{key}: run {md[key]['run_s']:.1f} s", flush=True)
    else:
        print("moordyn is not installed: jaxstring side only")
    ref_key = next(iter(md), None)
    ref = md.get(ref_key)
    shape_ts = [t for t in SHAPE_TIMES if t <= t1] or [t1]
    if t1 not in shape_ts:
        shape_ts.append(t1)
    rows = []
    everything = {**md, **{f"jaxstring {m}": r for m, r in runs.items()}}
    for name, r in everything.items():
        row = {
            "code": name,
            "ok": r.get("ok", True),
            "setup_s": r.get("compile_s", r.get("setup_s")),
            "run_s": r["run_s"],
            "cpu_s": r["cpu_s"],
            "repeats": r["repeats"],
            "dtM_s": r.get("dtM"),
            "steps": r.get("steps"),
            "max_abs_length_error": float(np.max(np.abs(r["length_error"]))),
        }
        if ref is not None:
            row["time_vs_md"] = r["run_s"] / ref["run_s"]
            for end in ("root", "fast"):
                F, Fr = r[f"{end}_force"], ref[f"{end}_force"]
                row[f"{end}_dF_rel"] = force_difference(ts, F, Fr)
                row[f"{end}_dF_rel_smooth"] = force_difference(ts, F, Fr, skip=1.0)
                row[f"{end}_dF_rel_median"] = force_difference(
                    ts, F, Fr, stat=np.median
                )
                row[f"{end}_F10_N"] = float(
                    np.linalg.norm(settled_force(ts, F, min(10.0, t1)))
                )
            for t in shape_ts:
                i = int(np.argmin(np.abs(ts - t)))
                row[f"shape_{t:g}s_m"] = shape_distance(r["nodes"][i], ref["nodes"][i])
        rows.append(row)
    tag = "_quick" if quick else ""
    cols = (
        "code ok setup_s run_s cpu_s repeats time_vs_md dtM_s steps "
        "max_abs_length_error root_F10_N fast_F10_N root_dF_rel fast_dF_rel "
        "root_dF_rel_smooth fast_dF_rel_smooth root_dF_rel_median "
        "fast_dF_rel_median"
    ).split() + [f"shape_{t:g}s_m" for t in shape_ts]
    write_table(
        f"tether_moordyn{tag}",
        rows,
        cols,
        f"Blintsov tether (tether_fixed, {t1:g} s): MoorDyn 2.7.2 vs jaxstring",
        notes=[
            f"Reference for all differences: {ref_key} (RK4, CFL {CFL}, critical "
            "axial damping). setup_s: MoorDyn Create + Init_NoIC + LoadState; "
            "jaxstring compile (first call minus median run). run_s / cpu_s: time "
            f"stepping only (wall / process CPU), median of `repeats`; "
            f"time_vs_md = run_s / run_s of {ref_key}, measured in the same run.",
            "Both start from jaxstring's initial arc at rest (MoorDyn's IC solver "
            "ignores currents, so it is skipped and the state is loaded); the line "
            "settles during 0-10 s.",
            "root_F10_N, fast_F10_N: |end force| averaged over 9.5-10 s (end of the "
            "settle phase; the forces still creep up by about 0.4 %/s there). "
            "*_dF_rel: max over t > 10 s (every 0.05 s) of |F - F_ref|/|F_ref|; "
            "*_smooth: without the 1 s after each kink of the schedule "
            "(t = 10, 35, 45 s and the last sample, 70 s), where the prescribed "
            "velocity jumps; *_median: the median over t > 10 s.",
            "jaxstring exact-central (full run only, a diagnostic): the exact "
            "tether with the drag evaluated on MoorDyn's element tangent (the "
            "direction between the neighbours) instead of jaxstring's (the link "
            "ahead of the element); see CentralTangentDrag.",
            "shape_*: max distance between the chains (resampled by index "
            "fraction), m. max_abs_length_error: max |L - sum of segment lengths|/L.",
            f"Mapping: Cd = c_n = {props['Cd']:g}; CdAx = {props['CdAx']:.5g} = the "
            "scene's Drag.CdAx, which like MoorDyn's CdAx acts on the wetted area "
            "pi d l (tether_fixed puts the paper's c_t = 0.1 on the projected area "
            "d l_e and so passes 0.1/pi); MoorDyn's axial drag measured on a "
            f"straight line in axial flow / 0.5 rho CdAx pi d l = {drag_ratio:.4f}. "
            f"Ca = CaAx = {props['Ca']:g} (jaxstring's added mass is isotropic), "
            f"mass/length {props['w']:.5g} kg/m = rho pi d^2/4 (neutral).",
        ],
    )
    if ref is not None:
        _summary(rows, ref_key, tag)
    _figure(ts, runs, md, ref_key, shape_ts, tag)
    return rows, {"ts": ts, "runs": runs, "md": md, "drag_ratio": drag_ratio}


def _summary(rows, ref_key, tag):
    """Append the headline numbers to the table's .md file."""
    from _common import results_dir

    ref = next(r for r in rows if r["code"] == ref_key)
    lines = ["", "### Summary (same run)", ""]
    for r in rows:
        if not r["code"].startswith("jaxstring"):
            continue
        shapes = ", ".join(
            f"{k[6:-2]}: {r[k]:.3f} m" for k in r if k.startswith("shape_")
        )
        lines.append(
            f"- {r['code']}: run time {r['run_s']:.3g} s vs MoorDyn "
            f"{ref['run_s']:.3g} s (wall ratio jaxstring/MoorDyn "
            f"{r['run_s'] / ref['run_s']:.2e}, CPU ratio "
            f"{r['cpu_s'] / ref['cpu_s']:.2e}; compile {r['setup_s']:.1f} s apart); "
            f"end forces at 9.5-10 s: root {r['root_F10_N']:.2f} N, running end "
            f"{r['fast_F10_N']:.2f} N (MoorDyn {ref['root_F10_N']:.2f} / "
            f"{ref['fast_F10_N']:.2f} N); max relative force difference after 10 s "
            f"root {100 * r['root_dF_rel_smooth']:.1f} %, running end "
            f"{100 * r['fast_dF_rel_smooth']:.1f} % (1 s after the kinks left out; "
            f"with them {100 * r['root_dF_rel']:.0f} % / "
            f"{100 * r['fast_dF_rel']:.0f} %; median "
            f"{100 * r['root_dF_rel_median']:.1f} % / "
            f"{100 * r['fast_dF_rel_median']:.1f} %); shape distance {shapes}; "
            f"max length error {r['max_abs_length_error']:.1e} (MoorDyn "
            f"{ref['max_abs_length_error']:.1e})."
        )
    for r in rows:
        if r["code"].startswith("MoorDyn") and r["code"] != ref_key:
            lines.append(
                f"- {r['code']} vs {ref_key}: force difference root "
                f"{100 * r['root_dF_rel_smooth']:.2f} %, running end "
                f"{100 * r['fast_dF_rel_smooth']:.2f} % (kinks left out), run time "
                f"x{r['run_s'] / ref['run_s']:.2f}, dtM {r['dtM_s']:.3g} s."
            )
    path = results_dir() / f"tether_moordyn{tag}.md"
    with open(path, "a") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def _figure(ts, runs, md, ref_key, shape_ts, tag):
    fig, axes = new_figure(3, 2, w=4.6, h=3.4)
    comps = ((0, "x"), (2, "z"))
    styles = {"exact": "--", "aceam": ":", "exact-central": "-."}
    for row, end in enumerate(("root", "fast")):
        for col, (c, name) in enumerate(comps):
            ax = axes[row][col]
            if ref_key is not None:
                ax.plot(
                    ts, md[ref_key][f"{end}_force"][:, c], "k-", lw=1.2, label="MoorDyn"
                )
            for m, r in runs.items():
                ax.plot(
                    ts,
                    r[f"{end}_force"][:, c],
                    styles.get(m, "-"),
                    lw=1,
                    label=f"jaxstring {m}",
                )
            ax.set_xlabel("t (s)")
            ax.set_ylabel(f"{end} force F{name} (N)")
            ax.grid(lw=0.3, alpha=0.5)
            ax.legend(fontsize=7)
    ax = axes[0][2]
    for t in shape_ts:
        i = int(np.argmin(np.abs(ts - t)))
        if ref_key is not None:
            X = md[ref_key]["nodes"][i]
            ax.plot(X[:, 0], X[:, 2], "k-", lw=1.2)
        for m, r in runs.items():
            X = r["nodes"][i]
            ax.plot(X[:, 0], X[:, 2], styles.get(m, "-"), lw=1)
        ax.annotate(f"{t:g} s", X[-1, [0, 2]], fontsize=7)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_aspect("equal")
    ax.set_title("shapes (black: MoorDyn)", fontsize=8)
    ax = axes[1][2]
    if ref_key is not None:
        for m, r in runs.items():
            for end, ls in (("root", "-"), ("fast", "--")):
                F, Fr = r[f"{end}_force"], md[ref_key][f"{end}_force"]
                rel = np.linalg.norm(F - Fr, axis=1) / np.linalg.norm(Fr, axis=1)
                ax.semilogy(ts, rel + 1e-16, ls, lw=0.8, label=f"{m} {end}")
        ax.set_ylim(1e-4, 10)
        ax.legend(fontsize=7)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("|F - F_MoorDyn| / |F_MoorDyn|")
    ax.grid(lw=0.3, alpha=0.5)
    fig.suptitle("Blintsov tether: end forces of MoorDyn and jaxstring", fontsize=9)
    savefig(fig, f"tether_moordyn{tag}")


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--repeats", type=int, default=0)
    a = p.parse_args()
    main(quick=a.quick or bool(os.environ.get("SMOKE_TEST")), repeats=a.repeats or None)
