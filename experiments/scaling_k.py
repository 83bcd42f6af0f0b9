"""Cost vs number of elements k at EA = 1e6, with the fitted exponent.

Question: how does run time grow with k = 10 ... 640 (the paper reports about k^2)
for the best jaxstring solver and for CVODE as an expert sets it up? The main peer
is CVODE-numba (jaxstring/testing/peers.py): the same equations in numba, CVODE BDF with
the band linear solver and the analytic band Jacobian (displacement variables) or
CVODE's band difference quotients ((eps, phi) variables). CVODE driving jaxstring's
own JAX functions through Python callbacks (jaxstring/testing/references.py, band
Jacobian from JAX) is a second, labelled row. The best jaxstring solver is the
fastest implicit adaptive one at the second k (every candidate runs at the first
two k). A configuration stops growing k when one run takes longer than the budget.
Settings: (eps, phi) by default, 2 s, alpha = 0.01 s, rtol = atol = 1e-7 for every
code; every code starts from jaxstring's initial state of the scene.

Two starts (``--start``):

* ``release`` (default, the paper's figures): straight, unstrained and at rest at
  90 degrees. With no tension at first, gravity bends the string at the pivot into
  a kink that runs down it; a finer string resolves a sharper kink, so the steps an
  accurate solution needs grow with k (k^0.7 for BDF here) whatever the solver.
* ``swing`` (displacement only): the string hanging in its exact discrete static
  equilibrium (each element stretched by the weight below it), given the velocity
  of a rigid rotation, omega = sqrt(2 g / l). Smooth: the solution has no
  mesh-scale features, so the steps should not grow with k, and the exponent
  measures the cost per step.

Times: wall (``run_s``) and process CPU, all threads (``cpu_s``), the median of
``--repeats`` runs after a first, untimed call (jaxstring's compile, numba's compile
or cache load, JAX's jit of the callback functions: ``compile_s``, apart). With
``--rounds N`` the best jaxstring solver and CVODE-numba are timed again in N
interleaved rounds (see ``main``). ``x_cvode_wall``, ``x_cvode_cpu``: a run's time
over CVODE-numba's at the same k.

Run: ``python experiments/scaling_k.py [--quick] [--formulation displacement]
[--start swing] [--peers cvode-numba,cvode-BDF] [--rounds 3] [--tol 1e-6]``
(``--peers``: ``cvode-numba`` and the names of jaxstring/testing/references.py, run on
JAX callbacks; ``none``: jaxstring alone).
"""

import importlib.util
import math

import _common as common
import harness
import numpy as np

import jaxstring
from jaxstring.testing import references


KS = (10, 20, 40, 80, 160, 320, 640)
ALPHA = 0.01  # Kelvin-Voigt damping (s), the scene's default, given to the peers
CVODE = "CVODE-numba"
NUMBA_PEER = "cvode-numba"


def swing_state(k, EA, l=1.0, mu=1.0, m_s=1.0, g=9.81):
    """Displacement-variables state: static hanging equilibrium + rigid rotation."""
    h = l / k
    tension = g * (m_s + mu * h * (k - 1 - np.arange(k)))  # element e, e = 0..k-1
    y = -np.cumsum(h * (1.0 + tension / EA))
    omega = math.sqrt(2.0 * g / l)
    zero = np.zeros(k)
    return np.stack([zero, y, -omega * y, zero], axis=1)


def fit_exponent(ks, times):
    """Least-squares slope of log(time) vs log(k) (nan with fewer than 2 points)."""
    if len(ks) < 2:
        return math.nan
    return float(np.polyfit(np.log(ks), np.log(times), 1)[0])


# The columns of this study's tables that have other names in a harness record.
NAMES = {"code": "solver", "wall_s": "run_s"}


def _codes(case, scene, ts, active, callbacks):
    """The codes `active` at one k: CVODE-numba (from the scene's initial state),
    callback peers (`callbacks`), and jaxstring solvers by name."""
    y0 = np.ravel(np.asarray(scene.y0, dtype=np.float64))
    codes = []
    for name in active:
        if name == CVODE:
            codes.append(harness.cvode_numba_code(case.peer(), ts, y0))
        elif name in callbacks:
            codes.append(harness.callback_code(
                scene, name, ts, label=f"{name} on JAX callbacks [band Jacobian]"
            ))  # fmt: skip
        else:
            codes.append(harness.jaxstring_code(scene, name, ts))
    return codes


def measure(code, tol, repeats, long_run_s=common.LONG_RUN_S):
    """One first call (or the peer's warm-up and a first call), then `repeats` timed
    runs (one where the first took longer than `long_run_s`; none where the first
    failed). Returns the row with `run_s`, `cpu_s` (medians), `repeats` and
    `compile_s`."""
    r = harness.repeat(code, tol, repeats, retry_failed=False, long_run_s=long_run_s)
    r.pop("walls", None)
    return harness.rows([r], NAMES, drop=())[0]


def _ratio(rows, k, field, r):
    cv = [x for x in rows if x["k"] == k and x["solver"].startswith(CVODE)]
    if not cv or not cv[0]["ok"] or not r["ok"]:
        return math.nan
    return r[field] / cv[0][field]


def main(
    quick=False,
    formulation="angle",
    ks=None,
    EA=1e6,
    solvers=None,
    repeats=None,
    tol=1e-7,
    budget_s=90.0,
    out_name="",
    start="release",
    peers=None,
    rounds=0,
    note="",
):
    """Run the k-scaling study; return (rows, exponents).

    `peers`: "cvode-numba" (the main peer) and names of jaxstring/testing/references.py
    (CVODE, IDA, scipy on jaxstring's JAX functions through callbacks); default
    cvode-numba and cvode-BDF (quick: cvode-numba).

    `note`: one more note for both tables (e.g. why the k stop where they do).

    `rounds` > 0: after the sequential pass (which compiles every k and picks the
    solver), time the best jaxstring solver and CVODE-numba again in `rounds`
    interleaved rounds (each round runs every k once, k = 40 ... 1280, jaxstring
    then CVODE-numba, then again) and report the medians over the rounds. A shared
    machine's slow phases then fall on all k and both codes alike instead of on
    whichever ran at the time, which moves a fitted exponent by up to 0.1 here.
    """
    common.set_quick(quick)
    ks = ks or ((4, 8) if quick else KS)
    t1 = 0.2 if quick else 2.0
    repeats = repeats or (1 if quick else 3)
    candidates = solvers or (["kvaerno5"] if quick else common.solver_names("implicit"))
    candidates = [
        n for n in candidates if n in jaxstring.SOLVERS and jaxstring.SOLVERS[n][1]
    ]
    if start not in ("release", "swing"):
        raise ValueError(f"start must be 'release' or 'swing'; got {start!r}")
    if start == "swing" and formulation != "displacement":
        raise ValueError("start='swing' is built for formulation='displacement'")
    avail = references.available()
    if peers is None:
        numba_ok = all(importlib.util.find_spec(m) for m in ("numba", "sksundae"))
        peers = [NUMBA_PEER] * numba_ok + ([] if quick else ["cvode-BDF"])
    use_numba = NUMBA_PEER in peers
    callbacks = [p for p in peers if p != NUMBA_PEER and avail.get(p)]
    ts = np.linspace(0.0, t1, 41)
    rows = []
    again = {}  # k -> [(row, code)] of the runs to re-time in `rounds`
    active = list(candidates) + ([CVODE] if use_numba else []) + callbacks
    best = None
    for i, k in enumerate(ks):
        y0 = swing_state(k, EA) if start == "swing" else None
        case = harness.PendulumCase(formulation, EA=EA, k=k, alpha=ALPHA, t1=t1,
                                    y0=y0)  # fmt: skip
        scene = case.scene()
        codes = _codes(case, scene, ts, active, callbacks)
        here = []
        for name, code in zip(list(active), codes):
            r = measure(code, tol, repeats)
            r.update(k=k, n_states=int(scene.y0.size))
            rows.append(r)
            here.append(r)
            again.setdefault(k, []).append((r, code))
            print(f"k={k} {code.label}: {r['run_s']:.3g} s wall, {r['cpu_s']:.3g} s "
                  f"CPU, ok={r['ok']}", flush=True)  # fmt: skip
            if not r["ok"] or r["run_s"] > budget_s:
                active.remove(name)
        # diff_m: the distance to CVODE-numba (else to the first successful run)
        ref = [r for r in here if r["ok"] and r["kind"] == "cvode"]
        ref = ref or [r for r in here if r["ok"]]
        for r in here:
            r["diff_m"] = (
                common.end_mass_error(r["end"], ref[0]["end"]) if r["ok"] else math.nan
            )
        if i == min(1, len(ks) - 1):
            # keep only the fastest jaxstring candidate from here on
            js = [r for r in here if r["ok"] and r["kind"] == "jaxstring"]
            if js:
                best = min(js, key=lambda r: r["run_s"])["solver"]
            active = [a for a in active if a == CVODE or a in callbacks or a == best]
    for r in rows:
        r.pop("end")
    if rounds > 0:
        redo = [
            [(r, c) for r, c in again[k]
             if r["ok"] and (c.label == best or c.kind == "cvode")]
            for k in ks if k in again
        ]  # fmt: skip
        # every k once per round, both codes (medians over the rounds)
        harness.retime(
            lambda: [pair for group in redo for pair in group],
            rounds,
            combine="median",
            after_round=lambda i, times: print(f"round {i}: " + ", ".join(
                f"{r['k']} {r['kind']} {times[id(r)][-1]:.3g}"
                for group in redo for r, _ in group)),
            wall="run_s",
        )  # fmt: skip
    for r in rows:
        r["x_cvode_wall"] = _ratio(rows, r["k"], "run_s", r)
        r["x_cvode_cpu"] = _ratio(rows, r["k"], "cpu_s", r)
    exps = []
    for name in dict.fromkeys(r["solver"] for r in rows):
        ok = [r for r in rows if r["solver"] == name and r["ok"]]
        if len(ok) >= 2:
            x = [r["k"] for r in ok]
            y = [r["run_s"] for r in ok]
            steps = [r.get("num_steps") for r in ok]
            exps.append(
                {
                    "solver": name,
                    "k_range": f"{min(x)}-{max(x)}",
                    "exponent": fit_exponent(x, y),
                    "exponent_cpu": fit_exponent(x, [r["cpu_s"] for r in ok]),
                    "exponent_upper_half": fit_exponent(
                        x[len(x) // 2 - 1 :], y[len(y) // 2 - 1 :]
                    )
                    if len(x) >= 3
                    else math.nan,
                    "best": name == best,
                    # peers report no step count
                    "steps_exponent": fit_exponent(x, steps)
                    if None not in steps
                    else math.nan,
                    "nfev_exponent": fit_exponent(x, [r["nfev"] for r in ok])
                    if all(r.get("nfev") is not None for r in ok)
                    else math.nan,
                }
            )
    tag = ("_quick" if quick else "") + (f"_{out_name}" if out_name else "")
    ratio_note = _ratio_note(rows, best)
    common.write_table(
        f"scaling_k{tag}",
        rows,
        (
            "k n_states solver ok run_s cpu_s repeats compile_s x_cvode_wall "
            "x_cvode_cpu num_steps num_rejected_steps nfev njev diff_m status"
        ).split(),
        f"Run time vs k, {formulation}, {start} start, EA={EA:g}, alpha={ALPHA:g} s, "
        f"t1={t1} s, rtol=atol={tol:g}",
        notes=[
            *([note] if note else []),
            *([ratio_note] if ratio_note else []),
            f"{CVODE}: CVODE BDF (scikit-sundae) with the band linear solver on the "
            "numba right-hand side of jaxstring/testing/peers.py (analytic band "
            "Jacobian in displacement variables, CVODE's band difference quotients "
            "otherwise), from jaxstring's initial state of the scene. 'on JAX "
            "callbacks': jaxstring's vector field and band Jacobian through "
            "Python callbacks (jaxstring/testing/references.py).",
            f"diff_m: largest end-mass distance at the {len(ts)} save times to "
            f"{CVODE} at the same k (to the first successful run where it failed).",
            "run_s (wall), cpu_s (process CPU, all threads): medians of `repeats` "
            "runs after a first, untimed call (a run over "
            f"{common.LONG_RUN_S:g} s is timed once)"
            + (
                f"; for the best jaxstring solver and {CVODE}, the medians over "
                f"{rounds} interleaved rounds (each round runs every k once, both "
                "codes) after all k were compiled."
                if rounds > 0
                else "."
            )
            + " compile_s: jaxstring's first call minus the median; the peers' "
            "numba compile or cache load, or JAX jit of the callback functions. "
            f"x_cvode_wall, x_cvode_cpu: time / {CVODE}'s at the same k.",
        ],
    )
    common.write_table(
        f"scaling_k_exponents{tag}",
        exps,
        (
            "solver best k_range exponent exponent_cpu exponent_upper_half "
            "steps_exponent nfev_exponent"
        ).split(),
        f"Fitted exponent p of run time ~ k^p (the paper: about 2), {formulation}, "
        f"start={start}, rtol=atol={tol:g}",
        notes=[
            *([note] if note else []),
            *([ratio_note] if ratio_note else []),
            "exponent: the fit of wall time over k_range, exponent_cpu of process "
            "CPU time, exponent_upper_half of wall time over the upper half of the "
            "k. steps_exponent: the same fit of the accepted step count (the rest of "
            "the exponent is the growth of the cost per step); nfev_exponent: of "
            "the right-hand-side calls (peers).",
        ],
    )
    fig, axes = common.new_figure(1, 1, w=6)
    ax = axes[0][0]
    for c, e in enumerate(exps):
        pts = [
            (r["k"], r["run_s"]) for r in rows if r["solver"] == e["solver"] and r["ok"]
        ]
        x, y = zip(*pts)
        kind = next(r["kind"] for r in rows if r["solver"] == e["solver"])
        ax.loglog(
            x,
            y,
            {"jaxstring": "-", "cvode": "--"}.get(kind, ":"),
            marker="o",
            ms=3,
            color=f"C{c}",
            label=f"{e['solver']}: k^{e['exponent']:.2f}",
        )
    if exps:
        x0 = np.array([ks[0], ks[-1]], float)
        y0 = min(r["run_s"] for r in rows if r["ok"])
        ax.loglog(x0, y0 * (x0 / x0[0]) ** 2, ":", color="gray", label="k^2")
    ax.set_xlabel("number of elements k")
    ax.set_ylabel("wall time (s)")
    ax.set_title(f"cost vs k, {formulation}, EA={EA:g}, {start}")
    ax.legend(fontsize=7)
    common.savefig(fig, f"scaling_k{tag}")
    return rows, exps


def _ratio_note(rows, best):
    """The best solver's wall and CPU time over CVODE-numba's, per k (or None)."""
    pts = [
        r
        for r in rows
        if r["solver"] == best and r["ok"] and math.isfinite(r["x_cvode_wall"])
    ]
    if not pts:
        return None
    return (
        f"{best} / {CVODE}, wall (CPU) per k: "
        + ", ".join(
            f"k={r['k']}: {r['x_cvode_wall']:.2g} ({r['x_cvode_cpu']:.2g})" for r in pts
        )
        + "."
    )


if __name__ == "__main__":
    common.run_study(
        main,
        lists={"ks": int, "solvers": str, "peers": str},
        formulation=dict(help="string formulation"),
        out_name=dict(
            flag="name",
            help="name of a variant study: files scaling_k_<name>.* (default: "
            "scaling_k.*)",
        ),
        start=dict(choices=("release", "swing")),
        budget_s=dict(flag="budget"),
        tol=dict(help="rtol = atol"),
        rounds=dict(help="re-time in interleaved rounds"),
        note=dict(help="one more note for the tables"),
    )
