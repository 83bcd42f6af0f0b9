"""MoorDyn's body, rod and beam test cases in MoorDyn and in jaxstring, in one run.

Question: on MoorDyn 2.7's own test decks with bodies, rods and bending stiffness
(shipped in jaxstring/lines/cases), how close do MoorDyn (the ``moordyn``
package, at each deck's time step, driven as MoorDyn's C++ tests drive it) and
jaxstring (``jaxstring.lines``, the solver and tolerance of jaxstring's tests)
come to each other and to the analytic value the test checks, and how long does
each take?

Cases (MoorDyn's tests ``bodies.cpp``, ``bodies_and_rods.cpp``, ``rods.cpp``,
``tripod.cpp``, ``beam.cpp``):

- orbitalBody: two free bodies whose mass sits off their reference point, started
  turning at 0.2 rad/s: the reference point orbits at radius 10 m and 0.2 rad/s
  (test: both within 1e-6 relative);
- rotatingBody: a free body turned by a line pulled round by a coupled point:
  where a point on the body is after each leg (test: within 0.15 m + 10 %) and
  the final turn, 90 deg about x (test: within 10 deg);
- pinnedBody: a pendulum on a pin accelerating at 0.5 m/s^2: its mean roll
  against atan(-a/g) (test: 1e-3 rad);
- bodyDrag: a free body falling onto its drag (test: it runs 5 s);
- BodiesAndRods.dat (static=False): a body with a fixed and a pinned rod, three
  lines and a buoyed cable sinking for 1 s (test: it runs, finite);
- RodHanging: a rod hung by two ropes is level after 10 s (test: 1 %);
- RodPinnedFloating: two buoyant rods pinned to the earth swing up (test: end B
  above end A after 10 s);
- rod_tests/AddedMass: a buoyant rod rises at a = (rho V - m) g / (m + rho V Ca)
  (test: every node within rtol 1e-8, atol 1e-10 m);
- tripod: nine free points joined by eleven lines with bending stiffness, among
  them a float crossing the surface, run 3 s (test: it runs); the points' paths;
- BeamCantilevered, BeamSimplySupported: the static deflection under the beam's
  weight against Euler-Bernoulli (test: each node within 50 %). MoorDyn: its
  initial-condition solve (Init); jaxstring: its static solve of the free nodes.

Times: MoorDyn, best of 3 of the whole run (Create, Init with its
initial-condition solve, the Step calls), at the deck's dtM and at its largest
stable step (the deck's doubled while the run stays finite and within 1.5 times
the deck step's distance from the reference); jaxstring, the deck read and static
solve (setup) apart, the first call (trace and compile, without a persistent
compilation cache) apart, the run best of 3 after compilation. Equal agreement:
jaxstring's fastest run, of the loosest tolerance at which it is as close to the
analytic solution (or to its own run at the tests' tolerance) as MoorDyn is and
the next tighter one, and its time then.

Run: ``python experiments/moordyn_bodies.py [--quick] [--whole-loops]`` (quick:
one repeat, without BodiesAndRods and RodPinnedFloating; ``--whole-loops``:
jaxstring with XLA:CPU's whole-loop kernels, as the ``jaxstring`` command runs
it, docs/performance.md, written to ``moordyn_bodies_whole_loops``). Writes
``results/moordyn_bodies.{md,csv}`` and the figures
``results/moordyn_bodies_{orbit,pinned,beams}.png`` (a full run copies them to
docs/img/).
"""

import contextlib
import math
import os
import re
import shutil
import struct
import tempfile

import _common as common
import equinox as eqx
import jax.numpy as jnp
import numpy as np

import jaxstring as js
from jaxstring import lines
from jaxstring._config import whole_loop_flags


G = 9.80665
RHO = 1025.0
DOCS_IMG = os.path.join(os.path.dirname(__file__), "..", "docs", "img")


# ---------------------------------------------------------------------------
# Timing and MoorDyn helpers


def best_of(fn, repeats):
    """(result of the fastest call, its wall s) of `repeats` calls of `fn`."""
    best = out = None
    for _ in range(max(repeats, 1)):
        res, wall, _ = common.clock(lambda: common.block(fn()))
        if best is None or wall < best:
            best, out = wall, res
    return out, best


def jaxstring_timed(fn, repeats):
    """First call (trace + compile + run) apart from the best of `repeats` calls
    after it: (result, compile s = first - best, best s)."""
    _, first, _ = common.clock(lambda: common.block(fn()))
    out, best = best_of(fn, repeats)
    return out, max(first - best, 0.0), best


def md_dt(system):
    import cmoordyn

    return float(cmoordyn.get_dt(system))


def md_time_after_step(t_int, dt, dtM):
    """MoorDyn's integrator time after Step(dt): sub-steps of at most dtM, each
    adding two half steps (the C API writes it back into t; the Python wrapper
    does not return it)."""
    left = dt
    while left > 0.0:
        h = min(dtM, left)
        t_int += 0.5 * h
        t_int += 0.5 * h
        left -= h
    return t_int


class Deck:
    """A copy of a packaged deck in a scratch folder (MoorDyn writes its output
    files beside the deck)."""

    def __init__(self, workdir, name):
        self.src = lines.case_path(name)
        self.path = os.path.join(workdir, os.path.basename(name))
        shutil.copy(self.src, self.path)

    def at_step(self, dtM):
        """A copy of the deck beside it with its time step dtM replaced."""
        text, n = re.subn(
            r"^\S+(\s+dtM\b)", f"{dtM!r}\\1", open(self.src).read(), flags=re.M
        )
        if n != 1:
            raise ValueError(f"{self.src}: no single dtM option")
        stem, ext = os.path.splitext(self.path)
        path = f"{stem}_dtM{dtM:.6g}{ext}"
        open(path, "w").write(text)
        return path


@contextlib.contextmanager
def md_system(path, x=(), xd=()):
    import moordyn

    with common.quiet_fd():
        system = moordyn.Create(path)
        moordyn.Init(system, list(x), list(xd))
        try:
            yield system
        finally:
            moordyn.Close(system)


def md_step(system, x, xd, t, dt):
    import moordyn

    with common.quiet_fd():
        moordyn.Step(system, list(x), list(xd), float(t), float(dt))


def rod_nodes(rod):
    import moordyn

    n = moordyn.GetRodN(rod)
    return np.array([moordyn.GetRodNodePos(rod, k) for k in range(n + 1)])


def _set_body_velocities(path, n_bodies, v6):
    """Set the velocities of the first `n_bodies` bodies in a MoorDyn state file
    (SaveState's layout: a 9-byte header, the size and number of instances, then
    each instance's rows x columns of doubles; a body's state is its position
    and quaternion (7) and its velocity (6))."""
    raw = open(path, "rb").read()
    head, words = raw[:9], list(struct.unpack(f"<{(len(raw) - 9) // 8}Q", raw[9:]))
    ptr = 2
    for inst in range(words[1]):
        rows, cols = words[ptr], words[ptr + 1]
        ptr += 2
        if inst < n_bodies:
            block = struct.pack("<13Q", *words[ptr : ptr + 13])
            vals = list(struct.unpack("<13d", block))
            vals[7:13] = list(v6)
            words[ptr : ptr + 13] = struct.unpack("<13Q", struct.pack("<13d", *vals))
        ptr += rows * cols
    open(path, "wb").write(head + struct.pack(f"<{len(words)}Q", *words))


# ---------------------------------------------------------------------------
# The cases: each returns (row, series for the figures)


def orbital_body(workdir, repeats):
    import moordyn

    radius, omega, r0 = 10.0, 0.2, np.array([0.0, 0.0, 20.0])
    deck = Deck(workdir, "body_tests/orbitalBody.txt")

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            n = moordyn.GetNumberBodies(s)
            bodies = [moordyn.GetBody(s, i + 1) for i in range(n)]
            state = os.path.join(workdir, "orbital.state")
            moordyn.SaveState(s, state)
            v6 = [0.0, 0.0, radius * omega, omega, 0.0, 0.0]
            _set_body_velocities(state, n, v6)
            moordyn.LoadState(s, state)
            md_step(s, [], [], 0.0, 1e-6)  # as MoorDyn's test: a first tiny step
            t = md_time_after_step(0.0, 1e-6, dtM)
            ts, pos = [], []
            while 10.0 - t > 0.025:
                md_step(s, [], [], t, 0.25)
                t = md_time_after_step(t, 0.25, dtM)
                ts.append(t)
                pos.append([moordyn.GetBodyState(b)[0][:3] for b in bodies])
        return np.array(ts), np.array(pos), dtM

    (t_md, p_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(deck.src, static=False, t1=float(t_md[-1]))
    )
    fr = scene.model.topology.frames
    y0 = scene.y0
    for f in (1, 2):
        y0 = y0.at[fr.trans_row[f], 3:].set(jnp.array([0.0, 0.0, radius * omega]))
        y0 = y0.at[fr.rot_rows[f][0], 3:].set(jnp.array([omega, 0.0, 0.0]))
    scene = eqx.tree_at(lambda s: s.y0, scene, y0)
    rtol = 1e-12
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=t_md), repeats
    )
    p_js = np.asarray(traj.obs["body_position"])

    def orbit_error(p, t):
        q = (p - r0) / radius
        err_r = np.abs(np.linalg.norm(p - r0, axis=-1) - radius) / radius
        err_w = np.abs(np.arctan2(q[..., 2], q[..., 1]) / t[:, None] - omega) / omega
        return float(max(np.max(err_r), np.max(err_w)))

    e_md, e_js = orbit_error(p_md, t_md), orbit_error(p_js, t_md)
    row = {
        "case": "orbitalBody", "quantity": "orbit radius and rate, largest rel. error",
        "test_limit": "1e-6", "moordyn": e_md, "jaxstring": e_js, "analytic": 0.0,
        "diff": float(np.max(np.abs(p_js - p_md))), "diff_of": "body positions (m)",
        "md_err": e_md, "js_err": e_js, "md_dtM": dtM, "md_s": md_s,
        "js_code": f"tsit5 rtol={rtol:g}", "js_ok": traj.ok, "js_setup_s": setup_s,
        "js_compile_s": comp, "js_run_s": run,
        "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    a = omega * t_md
    exact = r0 + radius * np.stack([0 * a, np.cos(a), np.sin(a)], 1)[:, None]
    row["_match"] = (
        scene, t_md, lambda tr: tr.obs["body_position"], p_md, p_js, exact
    )  # fmt: skip
    row["_md_step"] = (deck, lambda path: md_run(path)[1])
    return row, {"t": t_md, "md": p_md, "js": p_js, "r0": r0, "radius": radius}


def _rotating_body_path():
    """Coupled point 9 of MoorDyn's rotating-body test (as jaxstring's test):
    three quarter turns of radius 2 m about the body's centre c in 2 s each,
    sampled every 0.1 s, each followed by 0.5 s held 2.05 m from c; the times at
    the ends of the holds and where the point on the body should be then."""
    c = np.array([0.0, 0.0, 5.0])
    legs = [lambda a: (math.cos(a), 0, math.sin(a)),
            lambda a: (0, math.sin(a), math.cos(a)),
            lambda a: (math.sin(a), math.cos(a), 0)]  # fmt: skip
    ends = [(0, 0, 1.0), (0, 1.0, 0), (1.0, 0, 0)]
    T, X, checks = [0.0], [c + [2.0, 0, 0]], []
    t = 0.1
    for leg, e in zip(legs, ends):
        for i in range(21):
            T.append(t + 0.1 * i)
            X.append(c + 2.0 * np.array(leg(0.25 * math.pi * 0.1 * i)))
        t += 2.0
        T.append(t + 0.1)
        X.append(c + 2.05 * np.array(e))
        t += 0.5
        checks.append(t)
    T.append(t + 0.1)
    X.append(X[-1])
    return c, legs, np.array(T), np.array(X), np.array(checks), np.array(ends)


def _turn(R):
    """Angle (deg, in -180 .. 180) and axis of a rotation matrix."""
    w = 0.5 * math.sqrt(max(1.0 + np.trace(R), 0.0))
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / (4 * w)
    angle = math.degrees(2 * math.acos(min(w, 1.0)))
    return (angle + 180) % 360 - 180, v / np.linalg.norm(v)


def _euler_matrix(a):
    cx, sx, cy, sy, cz, sz = (f(x) for x in a for f in (math.cos, math.sin))
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rx @ Ry @ Rz


def rotating_body(workdir, repeats):
    import moordyn

    deck = Deck(workdir, "body_tests/rotatingBody.txt")
    c, legs, T, X, checks, ends = _rotating_body_path()
    dt = 0.1

    def md_run(path=deck.path):
        with md_system(path, c + [2.0, 0, 0], [0.0] * 3) as s:
            dtM = md_dt(s)
            point, body = moordyn.GetPoint(s, 8), moordyn.GetBody(s, 1)
            t = 0.0

            def step(x, xd, t):
                md_step(s, x, xd, t, dt)
                return md_time_after_step(t, dt, dtM)

            t = step(c + [2.0, 0, 0], np.zeros(3), t)
            p8 = []
            for leg, e in zip(legs, ends):
                a = 0.25 * math.pi * dt * np.arange(21)
                xs = [c + 2.0 * np.array(leg(ai)) for ai in a]
                for i in range(20):  # MoorDyn's test passes the step's displacement
                    t = step(xs[i], xs[i + 1] - xs[i], t)
                t0 = t
                while t < t0 + 0.5:
                    t = step(c + 2.05 * e, np.zeros(3), t)
                p8.append(np.array(moordyn.GetPointPos(point)) - c)
            R = _euler_matrix(moordyn.GetBodyState(body)[0][3:])
        return np.array(p8), R, dtM

    (p8_md, R_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(
            deck.src,
            static=False,
            motion={9: js.PrescribedEnd(T, X)},
            t1=float(checks[-1]),
        )  # fmt: skip
    )
    rtol = 1e-8
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=checks), repeats
    )

    def point8(tr):  # point 8, 1 m along the body's x axis
        return tr.obs["body_position"][:, 0] + tr.obs["body_rotation"][:, 0, :, 0]

    R = np.asarray(traj.obs["body_rotation"][:, 0])
    p8_js = np.asarray(point8(traj)) - c
    a_md, ax_md = _turn(R_md)
    a_js, ax_js = _turn(R[-1])
    row = {
        "case": "rotatingBody", "quantity": "final turn about x (deg)",
        "test_limit": "90 +- 10 deg; point within 0.15 m + 10 %",
        "moordyn": abs(a_md) * np.sign(-ax_md[0]),
        "jaxstring": abs(a_js) * np.sign(-ax_js[0]),
        "analytic": 90.0, "diff": float(np.max(np.abs(p8_js - p8_md))),
        "diff_of": "point on the body after each leg (m)",
        "md_err": float(np.max(np.abs(p8_md - ends))),
        "js_err": float(np.max(np.abs(p8_js - ends))), "md_dtM": dtM, "md_s": md_s,
        "js_code": f"tsit5 rtol={rtol:g}", "js_ok": traj.ok, "js_setup_s": setup_s,
        "js_compile_s": comp, "js_run_s": run,
        "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (scene, checks, lambda tr: point8(tr) - c, p8_md, p8_js)
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    return row, None


def pinned_body(workdir, repeats):
    import moordyn

    deck = Deck(workdir, "body_tests/pinnedBody.txt")
    a, dt = 0.5, 0.01

    def md_run(path=deck.path):
        x, xd = np.array([0, 0, -5.0, 0, 0, 0]), np.zeros(6)
        with md_system(path, x, xd) as s:
            dtM = md_dt(s)
            body = moordyn.GetBody(s, 1)
            roll, t, t_int, i, j = [], 0.0, 0.0, 0, 0
            while t < 50.0:  # MoorDyn's test loop
                x[1], xd[1] = 0.5 * a * t**2, a * t
                md_step(s, x, xd, t, dt)
                t_int = md_time_after_step(t_int, dt, dtM)
                t = t_int
                roll.append(moordyn.GetBodyState(body)[0][3])
                if (
                    i >= 30
                    and (roll[i] - roll[i - 1]) * (roll[i - 1] - roll[i - 2]) < 0
                ):
                    j += 1
                if j > 3:
                    break
                t, i = t + dt, i + 1
        return np.array(roll), dtM

    (roll_md, dtM), md_s = best_of(md_run, repeats)
    n = len(roll_md)
    ts = dt * np.arange(1, n + 1)
    motion = lines.RigidMotion(
        fn=lambda t, acc: jnp.stack([0 * t, 0.5 * acc * t**2, 0 * t, 0 * t, 0 * t,
                                     0 * t]),
        params=jnp.asarray(a),
    )  # fmt: skip
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(
            deck.src, static=False, motion={"body1": motion}, t1=float(ts[-1])
        )  # fmt: skip
    )
    rtol = 1e-9
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=ts), repeats
    )
    roll_js = np.asarray(traj.obs["body_angles"][:, 0, 0])
    theta = math.atan(-a / G)
    m_md, m_js = float(np.mean(roll_md)), float(np.mean(roll_js))
    row = {
        "case": "pinnedBody", "quantity": "mean roll over two swings (rad)",
        "test_limit": "atan(-a/g) +- 1e-3", "moordyn": m_md, "jaxstring": m_js,
        "analytic": theta, "diff": float(np.max(np.abs(roll_js - roll_md))),
        "diff_of": "roll (rad)", "md_err": abs(m_md - theta),
        "js_err": abs(m_js - theta), "md_dtM": dtM, "md_s": md_s,
        "js_code": f"tsit5 rtol={rtol:g}", "js_ok": traj.ok, "js_setup_s": setup_s,
        "js_compile_s": comp, "js_run_s": run,
        "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (
        scene,
        ts,
        lambda tr: tr.obs["body_angles"][:, 0, 0],
        roll_md,
        roll_js,
    )
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    return row, {"t": ts, "md": roll_md, "js": roll_js, "theta": theta}


def body_drag(workdir, repeats):
    import moordyn

    deck = Deck(workdir, "body_tests/bodyDrag.txt")

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            body = moordyn.GetBody(s, 1)
            ts, z, t = [0.0], [moordyn.GetBodyState(body)[0][2]], 0.0
            while t < 5.0:
                md_step(s, [], [], t, 0.1)
                t = md_time_after_step(t, 0.1, dtM)
                ts.append(t)
                z.append(moordyn.GetBodyState(body)[0][2])
        return np.array(ts), np.array(z), dtM

    (t_md, z_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(deck.src, static=False, t1=float(t_md[-1]))
    )
    rtol = 1e-9
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=t_md), repeats
    )
    z_js = np.asarray(traj.obs["body_position"][:, 0, 2])
    row = {
        "case": "bodyDrag", "quantity": "body height after 5 s (m)",
        "test_limit": "runs 5 s", "moordyn": z_md[-1], "jaxstring": z_js[-1],
        "diff": float(np.max(np.abs(z_js - z_md))), "diff_of": "body height (m)",
        "md_dtM": dtM, "md_s": md_s, "js_code": f"tsit5 rtol={rtol:g}",
        "js_ok": traj.ok, "js_setup_s": setup_s, "js_compile_s": comp,
        "js_run_s": run, "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (
        scene,
        t_md,
        lambda tr: tr.obs["body_position"][:, 0, 2],
        z_md,
        z_js,
    )
    row["_md_step"] = (deck, lambda path: md_run(path)[1])
    return row, None


def bodies_and_rods(workdir, repeats):
    import moordyn

    deck = Deck(workdir, "BodiesAndRods.dat")

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            body = moordyn.GetBody(s, 1)
            z = []
            for i in range(10):
                md_step(s, [], [], 0.1 * i, 0.1)
                z.append(moordyn.GetBodyState(body)[0][2])
        return np.array(z), dtM

    (z_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(deck.src, t1=1.0, static=False)
    )
    rtol = 1e-6
    ts = np.linspace(0.1, 1.0, 10)
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=ts), repeats
    )
    z_js = np.asarray(traj.obs["body_position"][:, 0, 2])
    row = {
        "case": "BodiesAndRods", "quantity": "body height after 1 s (m)",
        "test_limit": "runs 1 s, finite", "moordyn": z_md[-1], "jaxstring": z_js[-1],
        "diff": float(np.max(np.abs(z_js - z_md))), "diff_of": "body height (m)",
        "md_dtM": dtM, "md_s": md_s, "js_code": f"tsit5 rtol={rtol:g}",
        "js_ok": traj.ok, "js_setup_s": setup_s, "js_compile_s": comp,
        "js_run_s": run, "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (scene, ts, lambda tr: tr.obs["body_position"][:, 0, 2], z_md, z_js)
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    return row, None


def _rod_after_10s(workdir, name, repeats):
    """MoorDyn's rod tests' protocol: one 10 s Step; the rods' nodes then."""
    import moordyn

    deck = Deck(workdir, name)

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            rods = [moordyn.GetRod(s, i + 1) for i in range(moordyn.GetNumberRods(s))]
            md_step(s, [], [], 0.0, 10.0)
            nodes = np.concatenate([rod_nodes(r) for r in rods])
        return nodes, dtM

    (nodes_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(lambda: lines.read_moordyn(deck.src, t1=10.0))
    return deck, nodes_md, dtM, md_s, scene, setup_s, md_run


def rod_hanging(workdir, repeats):
    deck, nodes_md, dtM, md_s, scene, setup_s, md_run = _rod_after_10s(
        workdir, "RodHanging.txt", repeats
    )
    rtol = 1e-6
    ts = np.linspace(0.0, 10.0, 11)
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=ts), repeats
    )
    nodes_js = np.asarray(traj.obs["rod_nodes"][-1])

    def level(n):
        A, B = n[0], n[-1]
        return float(max((A[0] + 10) / 20, (B[0] - 10) / 20, abs(A[1]) / 20,
                         abs(B[1]) / 20, abs(A[2] - B[2]) / 20))  # fmt: skip

    row = {
        "case": "RodHanging", "quantity": "level criterion after 10 s (-)",
        "test_limit": "<= 0.01", "moordyn": level(nodes_md),
        "jaxstring": level(nodes_js), "analytic": 0.0,
        "diff": float(np.max(np.abs(nodes_js - nodes_md))),
        "diff_of": "rod nodes at 10 s (m)", "md_err": abs(level(nodes_md)),
        "js_err": abs(level(nodes_js)), "md_dtM": dtM, "md_s": md_s,
        "js_code": f"tsit5 rtol={rtol:g}", "js_ok": traj.ok, "js_setup_s": setup_s,
        "js_compile_s": comp, "js_run_s": run,
        "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (scene, ts, lambda tr: tr.obs["rod_nodes"][-1], nodes_md, nodes_js)
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    return row, None


def rod_pinned_floating(workdir, repeats):
    deck, nodes_md, dtM, md_s, scene, setup_s, md_run = _rod_after_10s(
        workdir, "RodPinnedFloating.txt", repeats
    )
    rtol = 1e-8
    ts = np.linspace(0.0, 10.0, 11)
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=ts), repeats
    )
    nodes_js = np.asarray(traj.obs["rod_nodes"][-1])
    zb_md, zb_js = (
        nodes_md.reshape(2, 2, 3)[0, 1, 2],
        nodes_js.reshape(2, 2, 3)[0, 1, 2],
    )
    row = {
        "case": "RodPinnedFloating", "quantity": "z of rod 1's end B after 10 s (m)",
        "test_limit": "end B above end A (-5 m)", "moordyn": zb_md,
        "jaxstring": zb_js, "diff": float(np.max(np.abs(nodes_js - nodes_md))),
        "diff_of": "rod nodes at 10 s (m)", "md_dtM": dtM, "md_s": md_s,
        "js_code": f"tsit5 rtol={rtol:g}", "js_ok": traj.ok, "js_setup_s": setup_s,
        "js_compile_s": comp, "js_run_s": run,
        "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (scene, ts, lambda tr: tr.obs["rod_nodes"][-1], nodes_md, nodes_js)
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    return row, None


def added_mass(workdir, repeats):
    import moordyn

    deck = Deck(workdir, "rod_tests/AddedMass.txt")
    m, V = 200.0, 2 * math.pi * 0.25**2
    acc = (RHO * V * G - m * G) / (m + RHO * V)

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            rod = moordyn.GetRod(s, 1)
            ts, z, t = [], [], 0.0
            while t < 2.5:
                md_step(s, [], [], t, 0.1)
                t = md_time_after_step(t, 0.1, dtM)
                ts.append(t)
                z.append(rod_nodes(rod)[:, 2])
                if -10 + 0.5 * acc * t * t > -1.0:
                    break
        return np.array(ts), np.array(z), dtM

    (t_md, z_md, dtM), md_s = best_of(md_run, repeats)
    scene, setup_s, _ = common.clock(
        lambda: lines.read_moordyn(deck.src, static=False, t1=float(t_md[-1]))
    )
    rtol = 1e-10
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "tsit5", rtol=rtol, atol=rtol, ts=t_md), repeats
    )
    z_js = np.asarray(traj.obs["rod_nodes"][:, :, 2])
    exact = (-10 + 0.5 * acc * t_md**2)[:, None]
    e_md, e_js = (
        float(np.max(np.abs(z_md - exact))),
        float(np.max(np.abs(z_js - exact))),
    )
    row = {
        "case": "AddedMass", "quantity": "largest node height error (m)",
        "test_limit": "rtol 1e-8, atol 1e-10 m", "moordyn": e_md, "jaxstring": e_js,
        "analytic": 0.0, "diff": float(np.max(np.abs(z_js - z_md))),
        "diff_of": "node heights (m)", "md_err": e_md, "js_err": e_js,
        "md_dtM": dtM, "md_s": md_s, "js_code": f"tsit5 rtol={rtol:g}",
        "js_ok": traj.ok, "js_setup_s": setup_s, "js_compile_s": comp,
        "js_run_s": run, "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (
        scene, t_md, lambda tr: tr.obs["rod_nodes"][:, :, 2], z_md, z_js,
        np.broadcast_to(exact, z_md.shape),
    )  # fmt: skip
    row["_md_step"] = (deck, lambda path: md_run(path)[1])
    return row, None


TRIPOD_DTM = 2.75e-5
"""MoorDyn's step on the tripod deck: half the deck's 5.5e-5 s, which is past
RK4's stability limit of the float's bending mode once a float node rises out of
the water (about 0.32 s; tests/lines/test_tripod.py): there MoorDyn's points
jump metres, though its run stays finite."""


def tripod(workdir, repeats):
    """MoorDyn's tripod test: the deck (nine free points, eleven lines with
    bending stiffness, a float crossing the surface) run 3 s in Steps of 0.1 s;
    the points' positions after each. jaxstring starts from MoorDyn's initial
    node positions (`jaxstring.testing.moordyn_start`)."""
    import moordyn

    from jaxstring.testing.moordyn_start import from_moordyn_nodes, point_nodes

    deck = Deck(workdir, "tripod.txt")
    base = deck.at_step(TRIPOD_DTM)

    def md_run(path=base):
        with md_system(path) as s:
            dtM = md_dt(s)
            n = moordyn.GetNumberPoints(s)
            points = [moordyn.GetPoint(s, i + 1) for i in range(n)]
            pos = [[moordyn.GetPointPos(p) for p in points]]
            for i in range(30):
                md_step(s, [], [], 0.1 * i, 0.1)
                pos.append([moordyn.GetPointPos(p) for p in points])
        return np.array(pos), dtM

    (p_md, dtM), md_s = best_of(md_run, repeats)
    ts = np.linspace(0.0, 3.0, 31)

    def read():
        scene = lines.read_moordyn(deck.src, t1=3.0, static=False)
        with md_system(base) as s:
            return from_moordyn_nodes(scene, moordyn, s)

    scene, setup_s, _ = common.clock(read)
    order = point_nodes(scene.model)

    def points(tr):
        return tr.obs["nodes"][:, order]

    # the reference: BDF at 1e-5 (9000 steps; at 1e-6 the float's fast modes are
    # resolved, over 30,000 steps for 0.6 s)
    rtol = 1e-5
    traj, comp, run = jaxstring_timed(
        lambda: js.simulate(scene, "bdf", rtol=rtol, atol=rtol, ts=ts), repeats
    )
    p_js = np.asarray(points(traj))
    moved = float(np.max(np.linalg.norm(p_md - p_md[0], axis=-1)))
    row = {
        "case": "tripod", "quantity": "largest point travel in 3 s (m)",
        "test_limit": "runs 3 s", "moordyn": moved,
        "jaxstring": float(np.max(np.linalg.norm(p_js - p_js[0], axis=-1))),
        "diff": float(np.max(np.abs(p_js - p_md))), "diff_of": "point positions (m)",
        "md_dtM": dtM, "md_s": md_s, "js_code": f"bdf rtol={rtol:g}",
        "js_ok": traj.ok, "js_setup_s": setup_s, "js_compile_s": comp,
        "js_run_s": run, "js_steps": int(traj.stats["num_steps"]),
    }  # fmt: skip
    row["_match"] = (scene, ts, points, p_md, p_js)
    row["_md_step"] = (deck, lambda path: md_run(path)[0])
    # Tsit5's step is held by the float's bending mode (about 5e4 rad/s): tens of
    # thousands of steps at any tolerance.
    row["_match_rtols"] = {"bdf": MATCH_RTOLS["bdf"]}
    return row, None


BEAM_L, BEAM_EI, BEAM_P = 10.0, 1.0e7, 100.0 * G


def euler_bernoulli(name, x):
    if name == "BeamCantilevered":
        return -BEAM_P * x**2 * (6 * BEAM_L**2 - 4 * x * BEAM_L + x**2) / (24 * BEAM_EI)
    return -BEAM_P * x * (BEAM_L**3 - 2 * x**2 * BEAM_L + x**3) / (24 * BEAM_EI)


def _beam_errors(name, x):
    """Largest deflection error over the largest deflection, and MoorDyn's
    test measure (each node's error over its own deflection)."""
    z, ze = x[:, 2] - 10.0, euler_bernoulli(name, x[:, 0])
    err = np.abs(z - ze)
    own = err / np.where(ze == 0, 1.0, np.abs(ze))
    return float(np.max(err) / np.max(np.abs(ze))), float(np.max(own))


def beam(workdir, repeats, name, segments):
    import moordyn

    deck = Deck(workdir, f"{name}.txt")

    def md_run(path=deck.path):
        with md_system(path) as s:
            dtM = md_dt(s)
            line = moordyn.GetLine(s, 1)
            n = moordyn.GetLineNumberNodes(line)
            x = np.array([moordyn.GetLineNodePos(line, i) for i in range(n)])
        return x, dtM

    (x_md, dtM), md_s = best_of(md_run, repeats)
    parsed, setup_s, _ = common.clock(lambda: lines.parse_moordyn(deck.src))
    nodes = {}
    comp = run = None
    for N in (*segments, None):
        d = lines.parse_moordyn(deck.src)
        if N is not None:
            d.lines[0]["segments"] = N

        def solve(d=d):
            scene = lines.deck_scene(d, free_points="solve")
            return scene.observables(scene.y0)["nodes"]

        if N is None:  # the deck's segments: timed
            x_js, comp, run = jaxstring_timed(solve, repeats)
            nodes[parsed.lines[0]["segments"]] = np.asarray(x_js)
        else:
            nodes[N] = np.asarray(solve())
    x_js = np.asarray(x_js)
    rel_md, own_md = _beam_errors(name, x_md)
    rel_js, own_js = _beam_errors(name, x_js)
    row = {
        "case": name,
        "quantity": "largest deflection error / largest deflection (-)",
        "test_limit": "each node within 50 % (worst node: md "
        f"{100 * own_md:.1f} %, js {100 * own_js:.1f} %)",
        "moordyn": rel_md, "jaxstring": rel_js, "analytic": 0.0,
        "diff": float(np.max(np.abs(x_js[:, 2] - x_md[:, 2]))),
        "diff_of": "node heights (m)", "md_err": rel_md, "js_err": rel_js,
        "md_dtM": dtM, "md_s": md_s, "js_code": "static solve (free_points='solve')",
        "js_ok": True, "js_setup_s": setup_s, "js_compile_s": comp, "js_run_s": run,
        "js_steps": None,
    }  # fmt: skip
    return row, {"md": x_md, "js": nodes}


def _distance(a, ref) -> float:
    """Largest |a - ref| over the samples both have (a MoorDyn run at another
    step may stop a sample earlier or later)."""
    a, ref = np.asarray(a), np.asarray(ref)
    n = min(len(a), len(ref))
    return float(np.max(np.abs(a[:n] - ref[:n])))


MD_GROWTH = 1.5
"""MoorDyn's step is grown while its run completes with finite values and its
distance from the reference stays within this factor of the deck step's (the rule
of the chain cases in moordyn_cases.py)."""

MD_MAX_STEP = 0.1
"""The largest MoorDyn step tried (s): the cases' coupling steps."""


def md_largest_step(md_step, dtM, md_dev, ref, repeats):
    """MoorDyn at its largest stable step: the deck's dtM doubled, then one
    geometric midpoint towards the first step that failed, while the run
    completes with finite values and stays within `MD_GROWTH` times the deck
    step's distance `md_dev` from `ref`. Returns (dtM, distance, best wall s) of
    the largest step that passed, or None where none above the deck's did."""
    deck, run = md_step

    def passes(dt):
        try:
            vals = np.asarray(run(deck.at_step(dt)), dtype=float)
        except RuntimeError:  # "MoorDyn reported an error integrating"
            return None
        if not np.all(np.isfinite(vals)):
            return None
        d = _distance(vals, ref)
        return d if d <= MD_GROWTH * md_dev + 1e-12 else None

    good, failed, dt = None, None, 2 * dtM
    while dt <= MD_MAX_STEP:
        d = passes(dt)
        if d is None:
            failed = dt
            break
        good, dt = (dt, d), 2 * dt
    if failed is not None:
        mid = math.sqrt((good[0] if good else dtM) * failed)
        d = passes(mid)
        if d is not None:
            good = (mid, d)
    if good is None:
        return None
    _, wall = best_of(lambda: run(deck.at_step(good[0])), repeats)
    return good[0], good[1], wall


# The solvers and tolerances tried for equal agreement, loosest first: the
# explicit Tsit5 of the tests and jaxstring's stiff BDF (a multistep method of
# order at most 5: not tried below 1e-6). BDF's error at loose tolerances does not
# fall evenly with rtol (BodiesAndRods: 0.0078 m at 1e-2, 0.0069 at 5e-3, 0.0058
# at 3e-3, 0.0006 at 2e-3), so it is tried at 1, 5, 3 and 2 per decade.
MATCH_RTOLS = {
    "tsit5": (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10),
    "bdf": tuple(m * 10.0**e for e in range(-3, -7, -1) for m in (10, 5, 3, 2)),
}


class Matcher:
    """jaxstring's runs of one case at the tolerances of MATCH_RTOLS, each
    simulated and timed once, against a reference `ref` in the compared
    quantity."""

    def __init__(self, scene, ts, pick, ref, repeats, rtols=None):
        self.scene, self.ts, self.pick, self.ref = scene, ts, pick, ref
        self.repeats, self.devs, self.walls = repeats, {}, {}
        self.rtols = MATCH_RTOLS if rtols is None else rtols

    def _sim(self, solver, rtol):
        return js.simulate(self.scene, solver, rtol=rtol, atol=rtol, ts=self.ts)

    def dev(self, solver, rtol):
        if (solver, rtol) not in self.devs:
            traj = self._sim(solver, rtol)
            d = _distance(self.pick(traj), self.ref)
            self.devs[solver, rtol] = d if traj.ok else math.inf
        return self.devs[solver, rtol]

    def wall(self, solver, rtol):
        if (solver, rtol) not in self.walls:
            _, run = best_of(lambda: self._sim(solver, rtol), self.repeats)
            self.walls[solver, rtol] = run
        return self.walls[solver, rtol]

    def match(self, target):
        """For each solver, its loosest tolerance whose run is within `target` of
        the reference and the next tighter one (a stability-bound explicit run
        can be faster there), the faster of the two; of the solvers, the fastest
        that agrees, else the closest run. Returns (solver, rtol, distance, wall
        s, agrees)."""
        found = []
        for solver, rtols in self.rtols.items():
            i = next(
                (k for k, r in enumerate(rtols) if self.dev(solver, r) <= target),
                None,
            )
            if i is None:
                r = min(rtols, key=lambda r: self.dev(solver, r))
                found.append((True, self.dev(solver, r), solver, r))
                continue
            for r in rtols[i : i + 2]:
                if self.dev(solver, r) <= target:
                    found.append((False, self.wall(solver, r), solver, r))
        _, _, solver, rtol = min(found)
        dev = self.dev(solver, rtol)
        return solver, rtol, dev, self.wall(solver, rtol), dev <= target


def matched(row, match, md_step, repeats, rtols=None):
    """jaxstring at equal agreement with MoorDyn, at the deck's step and at
    MoorDyn's largest stable step (`md_largest_step`): MoorDyn's largest distance
    in the compared quantity from the reference (the analytic solution where there
    is one, else jaxstring's run at the tests' tolerance), jaxstring's fastest
    run at least as close (`Matcher.match`) and the speed-ups."""
    scene, ts, pick, md, tight, *exact = match
    ref = np.asarray(exact[0] if exact else tight)
    md_dev = _distance(md, ref)
    m = Matcher(scene, ts, pick, ref, repeats, rtols)
    solver, rtol, dev, run, ok = m.match(md_dev)
    row.update(md_dev=md_dev, js_match_code=f"{solver} rtol={rtol:g}",
               js_match_dev=dev,
               match_ref="analytic" if exact else "jaxstring tight",
               match_ok=bool(ok), js_match_s=run,
               speedup_match=row["md_s"] / run)  # fmt: skip
    big = md_largest_step(md_step, row["md_dtM"], md_dev, ref, repeats)
    if big is None:
        big, code = (row["md_dtM"], md_dev, row["md_s"]), (solver, rtol, dev, run, ok)
    else:
        code = m.match(big[1])
    row.update(md_max_dtM=big[0], md_max_dev=big[1], md_max_s=big[2],
               js_max_code=f"{code[0]} rtol={code[1]:g}", js_max_dev=code[2],
               js_max_s=code[3], max_ok=bool(code[4]),
               speedup_max=big[2] / code[3])  # fmt: skip


# ---------------------------------------------------------------------------
# Figures


def figures(series, tag, docs):
    paths = []
    if "orbit" in series:
        s = series["orbit"]
        fig, axes = common.new_figure(1, 1, w=4.6, h=4.4)
        ax = axes[0][0]
        a = np.linspace(0, 2 * np.pi, 400)
        ax.plot(s["r0"][1] + s["radius"] * np.cos(a),
                s["r0"][2] + s["radius"] * np.sin(a), "k-", lw=0.6,
                label="radius 10 m about (0, 0, 20)")  # fmt: skip
        for b, mk in ((0, "o"), (1, "s")):
            ax.plot(s["md"][:, b, 1], s["md"][:, b, 2], f"C1{mk}", mfc="none",
                    ms=6, label=f"MoorDyn, body {b + 1}")  # fmt: skip
            ax.plot(s["js"][:, b, 1], s["js"][:, b, 2], f"C0{mk}", ms=2.5,
                    label=f"jaxstring, body {b + 1}")  # fmt: skip
        ax.set_aspect("equal")
        ax.set_xlabel("y (m)")
        ax.set_ylabel("z (m)")
        ax.set_title("orbitalBody: reference points every 0.25 s")
        ax.legend(fontsize=6, loc="lower left")
        paths.append(common.savefig(fig, f"moordyn_bodies_orbit{tag}"))
    if "pinned" in series:
        s = series["pinned"]
        fig, axes = common.new_figure(1, 1, w=6.0, h=3.4)
        ax = axes[0][0]
        ax.plot(s["t"], s["md"], "C1-", lw=2.2, alpha=0.6, label="MoorDyn (RK2, 1 ms)")
        ax.plot(s["t"], s["js"], "C0-", lw=0.9, label="jaxstring (Tsit5, 1e-9)")
        ax.axhline(s["theta"], color="k", ls="--", lw=0.8, label="atan(-a/g)")
        ax.set_xlabel("t (s)")
        ax.set_ylabel("roll (rad)")
        ax.set_title("pinnedBody: pendulum on a pin accelerating at 0.5 m/s²")
        ax.legend(fontsize=7)
        paths.append(common.savefig(fig, f"moordyn_bodies_pinned{tag}"))
    beams = [k for k in ("BeamCantilevered", "BeamSimplySupported") if k in series]
    if beams:
        fig, axes = common.new_figure(len(beams), 1, w=4.6, h=3.6)
        for ax, name in zip(axes[0], beams):
            s = series[name]
            x = np.linspace(0, BEAM_L, 200)
            ax.plot(x, 1e3 * euler_bernoulli(name, x), "k-", lw=1.0,
                    label="Euler-Bernoulli")  # fmt: skip
            for k, (N, xn) in enumerate(sorted(s["js"].items())):
                ax.plot(xn[:, 0], 1e3 * (xn[:, 2] - 10.0), f"C{k}.-", lw=0.7, ms=4,
                        label=f"jaxstring, {N} segments")  # fmt: skip
            ax.plot(s["md"][:, 0], 1e3 * (s["md"][:, 2] - 10.0), "C3x", ms=5,
                    label=f"MoorDyn, {len(s['md']) - 1} segments")  # fmt: skip
            ax.set_xlabel("x (m)")
            ax.set_ylabel("deflection (mm)")
            ax.set_title(name)
            ax.legend(fontsize=6)
        paths.append(common.savefig(fig, f"moordyn_bodies_beams{tag}"))
    if docs:
        os.makedirs(DOCS_IMG, exist_ok=True)
        for p in paths:
            dst = os.path.join(DOCS_IMG, os.path.basename(str(p)))
            shutil.copy(p, dst)
            print(f"figure: {os.path.normpath(dst)}")


# ---------------------------------------------------------------------------


def main(quick=False, repeats=None, whole_loops=False):
    """Run every case; return the rows. `whole_loops`: jaxstring's solves with
    XLA:CPU's whole-loop kernels (as in the `jaxstring` command; set here, before
    this process first runs XLA), written to moordyn_bodies_whole_loops."""
    if whole_loops:
        os.environ["XLA_FLAGS"] = whole_loop_flags(os.environ.get("XLA_FLAGS"))
    common.set_quick(quick)
    js.disable_compilation_cache()  # the first call of each case compiles
    repeats = repeats or (1 if quick else 3)
    cases = [
        ("orbit", orbital_body),
        (None, rotating_body),
        ("pinned", pinned_body),
        (None, body_drag),
        (None, bodies_and_rods),
        (None, rod_hanging),
        (None, rod_pinned_floating),
        (None, added_mass),
        (None, tripod),
        ("BeamCantilevered", lambda w, r: beam(w, r, "BeamCantilevered", (5, 10))),
        ("BeamSimplySupported",
         lambda w, r: beam(w, r, "BeamSimplySupported", (5, 10))),
    ]  # fmt: skip
    if quick:
        cases = [
            c
            for c in cases
            if c[1] not in (bodies_and_rods, rod_pinned_floating, tripod)
        ]
    rows, series = [], {}
    workdir = tempfile.mkdtemp(prefix="jaxstring_moordyn_bodies_")
    try:
        for key, fn in cases:
            row, s = fn(workdir, repeats)
            if "_match" in row:
                matched(
                    row,
                    row.pop("_match"),
                    row.pop("_md_step"),
                    repeats,
                    row.pop("_match_rtols", None),
                )
            row["speedup"] = row["md_s"] / row["js_run_s"]
            row["speedup_with_setup"] = row["md_s"] / (
                row["js_run_s"] + row["js_setup_s"]
            )
            row["load_1min"] = os.getloadavg()[0]
            rows.append(row)
            if key is not None:
                series[key] = s
            print({k: v for k, v in row.items()}, flush=True)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    tag = ("_whole_loops" if whole_loops else "") + ("_quick" if quick else "")
    columns = (
        "case quantity test_limit moordyn jaxstring analytic diff diff_of md_err "
        "js_err md_dtM md_s js_code js_ok js_steps js_setup_s js_compile_s js_run_s "
        "speedup md_dev match_ref js_match_code js_match_dev match_ok js_match_s "
        "speedup_match md_max_dtM md_max_dev md_max_s js_max_code js_max_dev "
        "max_ok js_max_s speedup_max speedup_with_setup load_1min"
    ).split()
    common.write_table(
        f"moordyn_bodies{tag}",
        rows,
        columns,
        "MoorDyn's body, rod and beam test cases: MoorDyn vs jaxstring"
        + (" (whole-loop kernels)" if whole_loops else ""),
        notes=[
            "quantity: what MoorDyn's test checks (or, where it only checks that the "
            "case runs, the state it ends in); moordyn, jaxstring: its value in each "
            "code; analytic: the test's value where there is one; md_err, js_err: "
            "each code's error against it (orbitalBody: the largest relative error "
            "of radius and rate; rotatingBody: the largest distance of the point on "
            "the body from where it should be, m; pinnedBody: |mean roll - "
            "atan(-a/g)|; beams: the largest deflection error over the largest "
            "deflection, Euler-Bernoulli).",
            "diff: the largest difference between the two codes in `diff_of` over "
            "the samples both take (MoorDyn's output times).",
            "MoorDyn: the moordyn package (MoorDyn 2.7) at the deck's dtM (md_dtM, "
            "s; beams: its initial-condition solve), driven as MoorDyn's C++ tests "
            "drive it; md_s: best of the repeats of the whole run (Create, Init, "
            "the Step calls).",
            "jaxstring: the solver and tolerance of jaxstring's tests (js_code); "
            "js_setup_s: deck read and static solve; js_compile_s: first call less "
            "the best run; js_run_s: best of the repeats after compilation (beams: "
            "the static solve of the free nodes, after compilation).",
            "equal agreement: md_dev, MoorDyn's largest distance in `diff_of` from "
            "the reference match_ref (the analytic solution, or jaxstring's run at "
            "the tests' tolerance, then md_dev = diff); js_match_code: for "
            "Tsit5 (rtol = atol = 1e-2 ... 1e-10) and BDF (1e-2, 5e-3, 3e-3, 2e-3, "
            "1e-3 ... 2e-6), the "
            "loosest tolerance whose run is at least as close to it and the next "
            "tighter one, the fastest of these runs (js_match_dev; match_ok False: "
            "no run was, the closest is timed); js_match_s: its best run time "
            "(compiled before timing); speedup_match: md_s / js_match_s.",
            "MoorDyn at its largest stable step: md_max_dtM, the deck's dtM "
            "doubled (at most 0.1 s), then one geometric midpoint towards the "
            "first step that failed, while MoorDyn's run completes with finite "
            "values and its distance from the reference stays within 1.5 md_dev "
            "(md_max_dev; the deck's step where no larger one passed); md_max_s: "
            "its best time; js_max_code, js_max_dev, max_ok, js_max_s: jaxstring "
            "matched to md_max_dev as above; speedup_max: md_max_s / js_max_s. "
            "tripod: MoorDyn from half the deck's dtM (the deck's 5.5e-5 s is past "
            "RK4's stability limit once a float node leaves the water), jaxstring "
            "matched with BDF only (Tsit5's step is held by the float's bending "
            "mode).",
            "speedup: md_s / js_run_s (> 1: jaxstring faster); speedup_with_setup: "
            "md_s / (js_run_s + js_setup_s). load_1min: the load average when the "
            "row was measured (the machine has 2 cores and is shared).",
        ],
    )
    if not whole_loops:
        figures(series, tag, docs=not quick)
    return rows


if __name__ == "__main__":
    common.run_study(
        main,
        whole_loops=dict(
            flag="whole-loops",
            action="store_true",
            help="jaxstring with XLA:CPU's whole-loop kernels (the command's setting)",
        ),
    )
