"""Cost vs number of elements k at EA = 1e6, with the fitted exponent.

Question: how does wall time grow with k = 10 ... 640 (the paper reports about k^2)
for the best jaxstring solver and for CVODE on the identical right-hand side (with
the JAX Jacobian in band form, so CVODE's band LU costs O(k) per factorisation)?
The best jaxstring solver is the fastest implicit adaptive one at the second k
(every candidate runs at the first two k). A configuration stops growing k when one
run takes longer than the budget. Settings: (eps, phi) by default, 2 s,
rtol = atol = 1e-7.

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

Run: ``python experiments/scaling_k.py [--quick] [--formulation displacement]
[--start swing] [--peers cvode-BDF] [--rounds 3] [--tol 1e-6]`` (``--rounds``:
re-time the jaxstring runs in interleaved rounds, see ``main``).
"""

import math
import time

import _common as common
import jax
import numpy as np
import references

import jaxstring


KS = (10, 20, 40, 80, 160, 320, 640)


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
):
    """Run the k-scaling study; return (rows, exponents).

    `rounds` > 0: after the sequential pass (which compiles every k and picks the
    solver), time every jaxstring run again in `rounds` interleaved rounds (each
    round runs every k once, k = 40 ... 1280, then again) and report the median over
    the rounds. A shared machine's slow phases then fall on all k alike instead of
    on whichever k was running, which moves a fitted exponent by up to 0.1 here.
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
        peers = ["cvode-BDF"] + ([] if quick else ["scipy-Radau"])
    peers = [(p, "jax-band") for p in peers if avail.get(p)]
    ts = np.linspace(0.0, t1, 41)
    rows = []
    timed_again = []  # (row, scene, solver) of the jaxstring runs, for `rounds`
    active = list(candidates) + [f"{p} [{j}]" for p, j in peers]
    best = None
    for i, k in enumerate(ks):
        y0 = swing_state(k, EA) if start == "swing" else None
        scene = jaxstring.scenes.string_pendulum(
            formulation=formulation, k=k, EA=EA, t1=t1, y0=y0
        )
        rhs = references.JaxRHS(scene)
        ref = None
        for name in list(active):
            if "[" in name:
                p, j = name.split(" [")
                r = common.run_peer(
                    rhs, p, j.rstrip("]"), ts, rtol=tol, atol=tol, repeats=repeats
                )
            else:
                r = common.run_jaxstring(
                    scene, name, ts, rtol=tol, atol=tol, repeats=repeats
                )
                timed_again.append((r, scene, name))
            end = r.pop("end")
            if ref is None and r["ok"]:
                ref = end
            r.update(
                k=k,
                n_states=int(scene.y0.size),
                diff_m=common.end_mass_error(end, ref) if r["ok"] else math.nan,
            )
            rows.append(r)
            print(f"k={k} {name}: {r['run_s']:.3g} s ok={r['ok']}", flush=True)
            if not r["ok"] or r["run_s"] > budget_s:
                active.remove(name)
        if i == min(1, len(ks) - 1):
            # keep only the fastest jaxstring candidate from here on
            js = [r for r in rows if r["k"] == k and r["ok"] and "[" not in r["solver"]]
            if js:
                best = min(js, key=lambda r: r["run_s"])["solver"]
            active = [a for a in active if "[" in a or a == best]
    if rounds > 0:
        again = [(r, sc, n) for r, sc, n in timed_again if r["ok"] and n == best]
        runs = {id(r): [] for r, _, _ in again}
        for i in range(rounds):
            for r, sc, n in again:
                t = time.perf_counter()
                jax.block_until_ready(
                    jaxstring.simulate(
                        sc, n, rtol=tol, atol=tol, ts=ts, max_steps=common.MAX_STEPS
                    ).ys
                )
                runs[id(r)].append(time.perf_counter() - t)
            print(
                f"round {i}: "
                + ", ".join(f"{runs[id(r)][-1]:.3g}" for r, _, _ in again)
            )
        for r, _, _ in again:
            r.update(run_s=float(np.median(runs[id(r)])), repeats=rounds)
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
                }
            )
    tag = ("_quick" if quick else "") + (f"_{out_name}" if out_name else "")
    common.write_table(
        f"scaling_k{tag}",
        rows,
        (
            "k n_states solver ok run_s repeats compile_s num_steps "
            "num_rejected_steps nfev njev diff_m status"
        ).split(),
        f"Wall time vs k, {formulation}, {start} start, EA={EA:g}, t1={t1} s, "
        f"rtol=atol={tol:g}",
        notes=[
            "diff_m: end-mass distance to the first successful run at the same k.",
            "run_s: median of `repeats` runs after a compile/warm-up run"
            + (
                f"; for jaxstring, the median over {rounds} interleaved rounds "
                "(each round runs every k once) after all k were compiled."
                if rounds > 0
                else "."
            ),
        ],
    )
    common.write_table(
        f"scaling_k_exponents{tag}",
        exps,
        "solver best k_range exponent exponent_upper_half steps_exponent".split(),
        f"Fitted exponent p of wall time ~ k^p (the paper: about 2), start={start}",
        notes=[
            "steps_exponent: the same fit of the accepted step count; the rest of "
            "the exponent is the growth of the cost per step."
        ],
    )
    fig, axes = common.new_figure(1, 1, w=6)
    ax = axes[0][0]
    for c, e in enumerate(exps):
        pts = [
            (r["k"], r["run_s"]) for r in rows if r["solver"] == e["solver"] and r["ok"]
        ]
        x, y = zip(*pts)
        ax.loglog(
            x,
            y,
            "--" if "[" in e["solver"] else "-",
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
    )
