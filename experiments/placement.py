"""Where one solve runs on a host with a GPU: the default placement against each device.

Question: on a machine with a GPU (JAX's default device there), is the default
`simulate` / `least_squares` of one scene (`SolveConfig.device="auto"`: the host
CPU) as fast as the faster of the two devices? Cases: the default string pendulum
(`js.string_pendulum()`: displacement variables, k = 40, EA = 1e6 N) simulated with
the "simulate" defaults, and a one-parameter `least_squares` of its damping alpha
to its own end-mass motion (k = 16, 51 save times). Each is run with
`device="auto"` (the default), `device="default"` (JAX's default device: the GPU)
and the host CPU named (`jax.devices("cpu")[0]`). Times: first call (trace and
compile included) and the median of three more calls.

Run: ``python experiments/placement.py`` (on a GPU host; on a CPU-only host every
row runs on the CPU).
"""

import argparse

import _common as common
import jax
import jax.numpy as jnp

import jaxstring as js


def _devices():
    return {
        "auto (default)": "auto",
        f"default device ({jax.default_backend()})": "default",
        "host CPU": jax.devices("cpu")[0],
    }


def _cases():
    scene = js.string_pendulum()
    small = js.string_pendulum(k=16, EA=1e3, alpha=0.05, t1=2.0)
    ts = jnp.linspace(0.0, 2.0, 51)
    data = js.simulate(small, ts=ts, device=jax.devices("cpu")[0]).end_mass
    start = js.string_pendulum(k=16, EA=1e3, alpha=0.07, t1=2.0)

    def residual(traj, scene):
        del scene
        return traj.end_mass - data

    return {
        "simulate, default pendulum (k = 40)": lambda d: (
            js.simulate(scene, device=d).end_mass
        ),
        "least_squares of alpha (k = 16)": lambda d: js.least_squares(
            start, residual, ["alpha"], ts=ts, device=d
        ).values["alpha"],
    }


def main(repeats=3):
    rows = []
    for case, call in _cases().items():
        for label, device in _devices().items():
            timing, _ = common.timed(lambda: call(device), repeats=repeats)
            row = dict(
                case=case,
                device=label,
                first_call_s=timing.first_s,
                compile_s=timing.compile_s,
                run_s=timing.run_s,
            )
            print(row, flush=True)
            rows.append(row)
    for case in _cases():
        sel = [r for r in rows if r["case"] == case]
        fastest = min(r["run_s"] for r in sel)
        for r in sel:
            r["run_vs_fastest"] = r["run_s"] / fastest
    gpu = jax.devices()[0]
    common.write_table(
        "placement",
        rows,
        ["case", "device", "first_call_s", "compile_s", "run_s", "run_vs_fastest"],
        f"One solve on each device of a host whose default device is "
        f"{gpu.platform} ({gpu.device_kind})",
        [
            "first_call_s: trace, compile and one run; run_s: median of "
            f"{repeats} further calls; compile_s: first call minus run_s.",
            "run_vs_fastest: run_s over the fastest device's run_s for the case.",
        ],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=3)
    main(repeats=p.parse_args().repeats)
