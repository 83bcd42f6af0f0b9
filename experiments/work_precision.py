"""Work-precision diagrams: end-mass error vs wall time, one curve per solver.

Question: what does accuracy cost? For each formulation and EA (1e4, 1e6, 1e8, and
1e9 for the headline), every adaptive jaxstring solver and the external references
(CVODE, IDA, scipy Radau/BDF/LSODA, all with the JAX Jacobian in band form on the
identical right-hand side) run at rtol = atol = 1e-3 ... 1e-10. The error is the
largest distance of the end mass from a reference at rtol = atol = 1e-12 computed by
a *different* solver (CVODE for jaxstring's solvers and Radau, scipy Radau for the
BDF-family peers; their mutual distance is reported as the reference floor).

Outputs the diagrams, the table, a headline table (time to reach a given accuracy,
and ratios jaxstring / CVODE / Radau in the same run) and the suggested presets.

Run: ``python experiments/work_precision.py [--quick]``.
"""

import math

import _common as common
import harness
import numpy as np

import jaxstring
from jaxstring.testing import references


FORMULATIONS = ("displacement", "natural", "angle")
EAS = (1e4, 1e6, 1e8, 1e9)
TOLS = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
PEER_JAC = "jax-band"
TARGETS = (1e-3, 1e-5, 1e-7)  # end-mass accuracy levels (m) for the headline
# The columns of this study's tables that have other names in a harness record.
NAMES = {"code": "solver", "wall_s": "run_s"}


def references_pair(scene, ts, tol, max_steps=1_000_000, rhs=None):
    """Two tight references from different solvers: (ref_a, label_a, ref_b, label_b).

    ref_a (CVODE, BDF) judges jaxstring's solvers and Radau; ref_b (scipy Radau,
    implicit Runge-Kutta) judges the BDF-family peers (CVODE, IDA, LSODA, scipy BDF).
    Without the peers installed, jaxstring's Kvaerno5 stands in.
    """
    avail = references.available()
    refs = []
    for peer in ("cvode-BDF", "scipy-Radau"):
        if avail[peer]:
            end, label = harness.reference(scene, ts, peer, tol, rhs=rhs)
            if end is not None:
                refs.append((end, label))
    if len(refs) < 2:
        refs.append(harness.reference(scene, ts, "kvaerno5", tol, max_steps=max_steps))
    (ref_a, lab_a), (ref_b, lab_b) = refs[0], refs[1]
    return ref_a, lab_a, ref_b, lab_b


def time_to_reach(rows, target):
    """Smallest run time among a curve's runs whose error is <= target (or nan)."""
    ok = [r["run_s"] for r in rows if r.get("ok") and r["err_m"] <= target]
    return min(ok) if ok else math.nan


def main(
    quick=False,
    formulations=None,
    EAs=None,
    tols=None,
    solvers=None,
    peers=None,
    repeats=None,
    ref_tol=1e-12,
    budget_s=60.0,
    out_name="",
):
    """Run the work-precision study; return (rows, headline rows)."""
    common.set_quick(quick)
    k = 8 if quick else 40
    t1 = 0.2 if quick else 2.0
    formulations = formulations or (("angle",) if quick else FORMULATIONS)
    EAs = EAs or ((1e6,) if quick else EAS)
    tols = tols or ((1e-4, 1e-6) if quick else TOLS)
    repeats = repeats or (1 if quick else 3)
    ref_tol = 1e-10 if quick else ref_tol
    names = solvers or (["kvaerno5"] if quick else common.solver_names("adaptive"))
    names = [n for n in names if n in jaxstring.SOLVERS and jaxstring.SOLVERS[n][1]]
    avail = references.available()
    peers = peers or (["cvode-BDF"] if quick else list(references.PEERS))
    peers = [p for p in peers if avail.get(p)]
    ts = np.linspace(0.0, t1, 41)
    rows, floors = [], []
    for form in formulations:
        for EA in EAs:
            scene = harness.PendulumCase(form, EA=EA, k=k, t1=t1).scene()
            rhs = references.JaxRHS(scene)
            ref_a, lab_a, ref_b, lab_b = references_pair(
                scene, ts, ref_tol, common.MAX_STEPS if quick else 1_000_000, rhs
            )
            floor = common.end_mass_error(ref_a, ref_b)
            floors.append(f"{form} EA={EA:g}: |{lab_a} - {lab_b}| = {floor:.2e} m")
            codes = [(harness.jaxstring_code(scene, n, ts), "js") for n in names]
            codes += [
                (harness.callback_code(scene, p, ts, label=f"{p} [{PEER_JAC}]",
                                       jac=PEER_JAC, rhs=rhs), "peer")
                for p in peers
            ]  # fmt: skip
            for code, kind in codes:
                for tol in tols:
                    # jaxstring: a first call, then the median of `repeats`; the
                    # peers: the callbacks' JIT compile apart, then the median
                    rec = harness.repeat(code, tol, repeats, first=kind == "js")
                    ref = ref_a if kind == "js" or "Radau" in code.label else ref_b
                    (r,) = harness.rows(harness.score([rec], ref), NAMES)
                    r.update(formulation=form, EA=EA, kind=kind)
                    rows.append(r)
                    print(
                        f"{form} EA={EA:g} {r['solver']} tol={tol:g}: "
                        f"{r['run_s']:.3g} s err={r['err_m']:.2e}",
                        flush=True,
                    )
                    if not r["ok"] or r["run_s"] > budget_s:
                        break  # tighter tolerances would only cost more
    tag = ("_quick" if quick else "") + (f"_{out_name}" if out_name else "")
    common.write_table(
        f"work_precision{tag}",
        rows,
        (
            "formulation EA solver tol ok err_m run_s repeats compile_s num_steps "
            "num_rejected_steps nfev njev status"
        ).split(),
        f"Work-precision: end-mass error vs wall time, k={k}, t1={t1} s",
        notes=[
            f"err_m: max end-mass distance (m) over 41 save times vs a reference at "
            f"rtol=atol={ref_tol:g} from a different solver (jaxstring solvers and "
            "Radau vs CVODE; CVODE, IDA, LSODA, scipy BDF vs Radau).",
            *floors,
            f"external solvers get the JAX Jacobian in band form ([{PEER_JAC}]).",
            "run_s: median of `repeats` runs after a compile/warm-up run.",
        ],
    )
    head = headline(rows, formulations, EAs, names, peers)
    common.write_table(
        f"work_precision_headline{tag}",
        head,
        (
            "formulation EA target_m best_jaxstring t_jaxstring_s t_cvode_s "
            "t_radau_s t_best_peer_s best_peer ratio_js_over_cvode "
            "ratio_js_over_radau"
        ).split(),
        "Time to reach an end-mass accuracy (min over tolerances), same run",
        notes=["ratio < 1: jaxstring faster. nan: no run reached the target."],
    )
    _plot(rows, formulations, EAs, tag)
    return rows, head


def headline(rows, formulations, EAs, names, peers):
    out = []
    for form in formulations:
        for EA in EAs:
            sel = [r for r in rows if r["formulation"] == form and r["EA"] == EA]
            for target in TARGETS:
                t_js = {
                    n: time_to_reach([r for r in sel if r["solver"] == n], target)
                    for n in names
                }
                t_pe = {
                    p: time_to_reach(
                        [r for r in sel if r["solver"] == f"{p} [{PEER_JAC}]"], target
                    )
                    for p in peers
                }
                good = {n: t for n, t in t_js.items() if np.isfinite(t)}
                best = min(good, key=good.get) if good else "-"
                tb = good.get(best, math.nan)
                pg = {p: t for p, t in t_pe.items() if np.isfinite(t)}
                bp = min(pg, key=pg.get) if pg else "-"
                tc = t_pe.get("cvode-BDF", math.nan)
                tr = t_pe.get("scipy-Radau", math.nan)
                out.append(
                    {
                        "formulation": form,
                        "EA": EA,
                        "target_m": target,
                        "best_jaxstring": best,
                        "t_jaxstring_s": tb,
                        "t_cvode_s": tc,
                        "t_radau_s": tr,
                        "best_peer": bp,
                        "t_best_peer_s": pg.get(bp, math.nan),
                        "ratio_js_over_cvode": tb / tc,
                        "ratio_js_over_radau": tb / tr,
                    }
                )
    return out


def _plot(rows, formulations, EAs, tag):
    fig, axes = common.new_figure(len(EAs), len(formulations), w=4.2, h=3.4)
    for i, form in enumerate(formulations):
        for j, EA in enumerate(EAs):
            ax = axes[i][j]
            sel = [r for r in rows if r["formulation"] == form and r["EA"] == EA]
            for c, who in enumerate(dict.fromkeys(r["solver"] for r in sel)):
                pts = sorted(
                    (r["run_s"], r["err_m"])
                    for r in sel
                    if r["solver"] == who and r["ok"] and r["err_m"] > 0
                )
                if pts:
                    x, y = zip(*pts)
                    ax.loglog(
                        x,
                        y,
                        "--" if "[" in who else "-",
                        marker="o",
                        ms=3,
                        color=f"C{c % 10}",
                        label=who,
                    )
            ax.set_title(f"{form}, EA={EA:g}", fontsize=9)
            ax.set_xlabel("wall time (s)")
            ax.set_ylabel("end-mass error (m)")
            ax.grid(True, which="major", alpha=0.3)
    axes[0][0].legend(fontsize=6)
    common.savefig(fig, f"work_precision{tag}")


if __name__ == "__main__":
    common.run_study(
        main,
        lists={**common.PENDULUM_LISTS, "tols": float, "peers": str},
        out_name=dict(
            flag="name",
            default="",
            help="name of a variant study: files work_precision_<name>.* "
            "(default: work_precision.*)",
        ),
    )
