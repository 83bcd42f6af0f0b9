"""``jaxstring sweep SCENE --vary NAME=LOW:HIGH:COUNT [...]``: a parameter sweep of a
named scene from the command line.

Each member's summary (status, steps, and the scene's summary quantities) goes to
``<out>/<scene>_sweep.csv`` and ``.npz``, with a figure of the quantities against the
varied parameters (``.png``). The members run in groups (`--batch-size`), over the
host's cores (`--processes`), with a progress line per group of chunks.
"""

import math
import os
import sys
import time


def add_parser(commands, scenes, common_arguments) -> None:
    """The ``sweep`` command, one subcommand per scene of `scenes` (the run
    command's `SceneRunner`s)."""
    sweep = commands.add_parser("sweep", help="sweep parameters of a named scene")
    scene_parsers = sweep.add_subparsers(
        dest="scene",
        metavar="SCENE",
        required=True,
        help="one of: " + ", ".join(scenes),
    )
    for name, runner in scenes.items():
        sp = scene_parsers.add_parser(name, help=runner.help, description=runner.help)
        runner.add_arguments(sp)
        common_arguments(sp, runner.solver)
        sp.add_argument(
            "--vary",
            action="append",
            required=True,
            metavar="NAME=LOW:HIGH:COUNT",
            help="a parameter of the scene and COUNT values from LOW to HIGH "
            "(repeat for several parameters: one member per row, or per combination "
            "with --grid)",
        )
        sp.add_argument(
            "--grid", action="store_true", help="every combination of the values"
        )
        sp.add_argument(
            "--processes",
            type=int,
            default=None,
            help="worker processes (default: every core when the sweep is large)",
        )
        sp.add_argument(
            "--batch-size", dest="batch_size", type=int, default=16,
            help="members per group (default 16)",
        )  # fmt: skip


def parse_vary(texts) -> dict:
    """`NAME=LOW:HIGH:COUNT` specifications -> {name: (low, high, count)}; a
    ValueError naming the specification and the valid form for anything else."""
    out = {}
    for text in texts:
        name, sep, spec = text.partition("=")
        parts = spec.split(":")
        form = "NAME=LOW:HIGH:COUNT, e.g. alpha=0.005:0.05:64"
        if not sep or not name or len(parts) != 3:
            raise ValueError(f"--vary {text!r}: must be {form}.")
        try:
            low, high = float(parts[0]), float(parts[1])
            count = int(parts[2])
        except ValueError:
            raise ValueError(
                f"--vary {text!r}: LOW and HIGH must be numbers and COUNT an integer "
                f"({form})."
            ) from None
        if not (math.isfinite(low) and math.isfinite(high)):
            raise ValueError(f"--vary {text!r}: LOW and HIGH must be finite.")
        if count < 1:
            raise ValueError(f"--vary {text!r}: COUNT must be >= 1; got {count}.")
        if name in out:
            raise ValueError(
                f"--vary names {name!r} twice; valid: each parameter once."
            )
        out[name] = (low, high, count)
    return out


def summary(traj, scene):
    """The per-member quantities of a sweep: the largest tension (where the model
    has one), the final position of the last node and the final energy."""
    import jax.numpy as jnp

    del scene
    obs = traj.obs
    out = {}
    if "tension" in obs:
        out["max_tension_N"] = jnp.nanmax(jnp.abs(obs["tension"]))
    pos = obs.get("nodes", obs.get("positions"))
    if pos is not None and pos.ndim == 3:
        last = pos[jnp.maximum(traj.n_valid - 1, 0), -1]
        for i, axis in enumerate("xyz"[: pos.shape[-1]]):
            out[f"end_{axis}_m"] = last[i]
    if "energy" in obs:
        out["energy_end_J"] = obs["energy"][jnp.maximum(traj.n_valid - 1, 0)]
    out["t_end_s"] = traj.t_end
    return out


def run(args, runner) -> int:
    """Run the sweep command; the exit code."""
    try:
        vary = parse_vary(args.vary)
        if args.processes is not None and args.processes < 1:
            raise ValueError(f"--processes must be >= 1; got {args.processes}.")
        if args.batch_size < 1:
            raise ValueError(f"--batch-size must be >= 1; got {args.batch_size}.")
        scene = runner.build(args)
        os.makedirs(args.out, exist_ok=True)
    except (ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2

    import numpy as np

    import jaxstring as js

    values = {n: np.linspace(lo, hi, c) for n, (lo, hi, c) in vary.items()}
    if args.grid:
        mesh = np.meshgrid(*values.values(), indexing="ij")
        values = {n: m.ravel() for n, m in zip(values, mesh)}
    elif len({v.size for v in values.values()}) > 1:
        print(
            "error: --vary counts must be equal without --grid; got "
            + ", ".join(f"{n}: {v.size}" for n, v in values.items()),
            file=sys.stderr,
        )
        return 2
    n = next(iter(values.values())).size
    options = dict(solver=args.solver, rtol=args.rtol, atol=args.atol)
    processes = "auto" if args.processes is None else args.processes
    # Progress over slices of the members (each a whole number of groups; one
    # compiled program serves every slice).
    groups = math.ceil(n / args.batch_size)
    per = max(1, math.ceil(groups / 10)) * args.batch_size
    pieces, start = [], time.perf_counter()
    try:
        for lo in range(0, n, per):
            part = {k: v[lo : lo + per] for k, v in values.items()}
            pieces.append(
                js.sweep(
                    scene,
                    part,
                    summary,
                    batch_size=args.batch_size,
                    processes=processes,
                    **options,
                )  # fmt: skip
            )
            done = min(n, lo + per)
            print(
                f"\rsweep {args.scene}: {done}/{n} members, "
                f"{time.perf_counter() - start:.1f} s",
                end="" if done < n else "\n",
                file=sys.stderr,
                flush=True,
            )
    except ValueError as e:
        print(f"\nerror: {e}", file=sys.stderr)
        return 2
    table = {k: np.concatenate([p.values[k] for p in pieces]) for k in values}
    out = {
        k: np.concatenate([np.asarray(p.out[k]) for p in pieces]) for k in pieces[0].out
    }
    ok = np.concatenate([p.ok for p in pieces])
    steps = np.concatenate([p.stats["num_accepted_steps"] for p in pieces])
    status = [s for p in pieces for s in p.status]
    stem = os.path.join(args.out, f"{args.scene}_sweep")
    columns = list(table) + ["ok", "status", "accepted_steps"] + list(out)
    with open(stem + ".csv", "w") as f:
        f.write(",".join(columns) + "\n")
        for i in range(n):
            row = [f"{table[k][i]:.10g}" for k in table]
            row += [str(bool(ok[i])), status[i].replace(",", ";"), str(int(steps[i]))]
            row += [f"{out[k][i]:.10g}" for k in out]
            f.write(",".join(row) + "\n")
    np.savez(stem + ".npz", ok=ok, status=np.asarray(status), steps=steps,
             **{f"value_{k}": v for k, v in table.items()}, **out)  # fmt: skip
    _figure(table, out, ok, stem + ".png", args.scene)
    print(
        f"{n} members, {int(ok.sum())} succeeded, {time.perf_counter() - start:.1f} s\n"
        f"wrote {stem}.csv\nwrote {stem}.npz\nwrote {stem}.png"
    )
    return 0 if ok.all() else 1


def _figure(table, out, ok, path, title):
    import matplotlib.pyplot as plt
    import numpy as np

    x_name = next(iter(table))
    x = table[x_name]
    names = list(out)
    fig, axes = plt.subplots(len(names), 1, figsize=(6, 1.8 * len(names)), sharex=True)
    axes = np.atleast_1d(axes)
    for ax, name in zip(axes, names):
        ax.plot(x[ok], out[name][ok], ".", ms=3)
        if (~ok).any():
            ax.plot(x[~ok], np.zeros((~ok).sum()), "rx", ms=4, label="failed")
        ax.set_ylabel(name, fontsize=8)
    axes[-1].set_xlabel(x_name)
    axes[0].set_title(f"{title}: sweep of {', '.join(table)}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
