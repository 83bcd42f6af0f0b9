"""Where a sweep's step spends its time: the compiled kernels, by part of the BDF step.

Question: a vmapped adaptive sweep on a saturated device runs at a fixed number of
members per second; which parts of a step take that time -- the vector field, the
Jacobian, the factorisation, the linear solves, the rest of the Newton iteration, or
the step control and diffrax's loop -- and how many kernels does a step launch?
Case: the default pendulum (displacement variables, k = 40, EA = 1e6 N, alpha in
[0.005, 0.05] s) as one `sweep` group of `--members` members (default: 16,384 on a
GPU, which saturate it, 64 on a CPU) over the first `--t1` seconds, BDF at rtol =
atol = 1e-6 (the sweep's defaults). The first call compiles (not profiled); a
second call of the same
program runs under `jax.profiler`.

On a CPU every kernel's trace event costs time of its own, so the traced call runs
several times longer than the untraced one (both are reported) and the parts made
of many small kernels weigh more in it; the kernel counts are exact. On a GPU the
kernels are timed on the device.

Each kernel of the trace (a fusion of the compiled program, named by its `hlo_op`)
is attributed to the innermost named part of the step from the `op_name` metadata of
that operation in the optimised program (an XLA dump of this process): the
`vector_field`, `jacobian` and `newton` scopes that this script puts around the
vector field, the BDF step's Jacobian and its chord iteration (`name_the_parts`;
jaxstring itself carries no such scopes: they lengthened the compilation of a
sweep by a fifth), the jitted `factor` and `block_solve`, and the rest (step-size
and order control, diffrax's loop, saving). Times are per loop iteration of the
group (the accepted and rejected steps of its slowest member).

Run: ``python experiments/sweep_profile.py [--members M] [--t1 T] [--name N]``.
Writes results/<name>.{md,csv} (by part) and results/<name>_kernels.{md,csv} (the
kernels that take the most time); <name> is sweep_profile, or sweep_profile_gpu
on a GPU.
"""

import os
import re
import tempfile


_DUMP = tempfile.mkdtemp(prefix="jaxstring_hlo_")
# One process's optimised programs, for the kernels' source names; the programs
# must be compiled here (not read from a compilation cache) for the dump.
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "")
    + f" --xla_dump_to={_DUMP} --xla_dump_hlo_as_text --xla_dump_hlo_pass_re=^$"
    # On a GPU, one kernel per trace event (no CUDA graphs of several kernels).
    + " --xla_gpu_enable_command_buffer="
).strip()
os.environ["JAXSTRING_CACHE"] = "off"

import argparse  # noqa: E402
import collections  # noqa: E402
import glob  # noqa: E402
import time  # noqa: E402

import _common as common  # noqa: E402
import jax  # noqa: E402
import numpy as np  # noqa: E402

import jaxstring as js  # noqa: E402


K, EA = 40, 1e6
RANGE = (0.005, 0.05)
PARTS = (
    "Jacobian",
    "factorisation",
    "linear solves",
    "vector field",
    "Newton (rest)",
    "step control and loop",
)


def _scoped(fn, name):
    def wrapper(*args, **kwargs):
        with jax.named_scope(name):
            return fn(*args, **kwargs)

    return wrapper


def name_the_parts():
    """Put named scopes around the vector field, the BDF step's Jacobian and its
    Newton iteration, for the source names of their operations (before tracing)."""
    from jaxstring import _scene
    from jaxstring._solvers import bdf

    _scene._traced_vector_field = _scoped(_scene._traced_vector_field, "vector_field")
    bdf.BDF._jacobian = _scoped(bdf.BDF._jacobian, "jacobian")
    bdf.newton_chord = _scoped(bdf.newton_chord, "newton")


def part_of(op_name: str) -> str:
    """The part of the BDF step an operation belongs to, from its source name."""
    if "jacobian" in op_name:
        return "Jacobian"
    if "jit(factor)" in op_name:
        return "factorisation"
    if "jit(block_solve)" in op_name:
        return "linear solves"
    if "vector_field" in op_name:
        return "vector field"
    if "newton" in op_name:
        return "Newton (rest)"
    return "step control and loop"


_INSTR = re.compile(r'^\s*(?:ROOT\s+)?%?([\w.\-]+) = .*?op_name="([^"]*)"')
_CONTROL = re.compile(r"\s(while|conditional|call)\(")


def source_names(dump_dir: str) -> dict:
    """hlo op name -> op_name metadata, from the largest optimised program that
    holds a diffrax solve (the sweep's)."""
    files = sorted(
        glob.glob(os.path.join(dump_dir, "*after_optimizations.txt")),
        key=os.path.getsize,
        reverse=True,
    )
    for f in files:
        text = open(f).read()
        if "diffeqsolve" not in text:
            continue
        names = {}
        for line in text.splitlines():
            m = _INSTR.match(line)
            # Control flow (while, conditional, call) holds other kernels: not
            # counted itself.
            if m and not _CONTROL.search(line.split(" = ", 1)[1]):
                names.setdefault(m.group(1), m.group(2))
        return names
    return {}


def kernel_times(trace_dir: str, names: dict) -> dict:
    """hlo op name -> [launches, total ns] of the sweep program's kernels in the
    trace: a GPU's "XLA Ops" line, or XLA:CPU's threads."""
    path = sorted(glob.glob(f"{trace_dir}/**/*.xplane.pb", recursive=True))[-1]
    data = jax.profiler.ProfileData.from_file(path)
    out = collections.defaultdict(lambda: [0, 0.0])
    gpu = [p for p in data.planes if p.name.startswith("/device:GPU")]
    planes = gpu[:1] or [p for p in data.planes if p.name == "/host:CPU"]
    for plane in planes:
        lines = list(plane.lines)
        ops = [ln for ln in lines if ln.name == "XLA Ops"]
        for line in ops or lines:
            for ev in line.events:
                stats = dict(ev.stats)  # noqa: PLW2901
                op = stats.get("hlo_op", ev.name if gpu else None)
                if op is None or op not in names:
                    continue
                out[op][0] += 1
                out[op][1] += ev.duration_ns
    return out


def linear_algebra_ms(members: int, n: int = K, repeats: int = 20) -> float:
    """Milliseconds for the factorisation and three solves of `members` block-
    tridiagonal Newton matrices of n 2 x 2 blocks (the reduced matrices of the
    string's step; `block_factor` and `block_solve`, jitted apart), best of
    `repeats` after a first call."""
    from jaxstring._linalg import banded

    rng = np.random.default_rng(0)
    lo, up = (0.1 * rng.normal(size=(members, n, 2, 2)) for _ in range(2))
    diag = 0.1 * rng.normal(size=(members, n, 2, 2)) + 4 * np.eye(2)
    rhs = rng.normal(size=(members, n, 2))

    def one(lo, diag, up, f):
        fac = banded.block_factor(banded.BlockTridiagonal(lo, diag, up, n, 2, 1))
        for _ in range(3):
            f = banded.block_solve(fac, f)
        return f

    fn = jax.jit(jax.vmap(one))
    fn(lo, diag, up, rhs).block_until_ready()
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn(lo, diag, up, rhs).block_until_ready()
        best = min(best, time.perf_counter() - t)
    return best * 1e3


def main(members=None, t1=0.05, name=None, keep=None):
    name_the_parts()
    gpu = jax.default_backend() != "cpu"
    members = members or (16384 if gpu else 64)
    name = name or ("sweep_profile_gpu" if gpu else "sweep_profile")
    scene = js.string_pendulum(k=K, EA=EA, t1=t1)
    alphas = np.linspace(*RANGE, members)

    def end_mass(traj, scene):
        del scene
        return traj.end_mass

    def call():
        return js.sweep(
            scene,
            {"alpha": alphas},
            end_mass,
            ts=np.array([0.0, t1]),
            processes=1,
            batch_size=members,
        )

    first = call()
    plain = call()  # the same call untraced: what tracing itself costs
    trace_dir = tempfile.mkdtemp(prefix="jaxstring_trace_")
    with jax.profiler.trace(trace_dir):
        res = call()
    iters = int(np.asarray(res.stats["num_steps"]).max())  # accepted + rejected
    if keep:  # the raw trace and programs, for a closer look elsewhere
        import shutil

        os.makedirs(keep, exist_ok=True)
        for f in glob.glob(f"{trace_dir}/**/*.xplane.pb", recursive=True):
            shutil.copy(f, keep)
        dumps = glob.glob(os.path.join(_DUMP, "*after_optimizations.txt"))
        for f in sorted(dumps, key=os.path.getsize)[-2:]:
            shutil.copy(f, keep)
    names = source_names(_DUMP)
    kernels = kernel_times(trace_dir, names)
    total = sum(v[1] for v in kernels.values())
    by_part = collections.defaultdict(lambda: [0, 0.0])
    for op, (n, ns) in kernels.items():
        p = part_of(names[op])
        by_part[p][0] += n
        by_part[p][1] += ns
    device = jax.devices()[0]
    where = f"{device.platform} ({device.device_kind})" if gpu else "CPU, one process"
    rows = [
        dict(
            part=p,
            kernels_per_step=by_part[p][0] / iters,
            ms_per_step=by_part[p][1] / iters / 1e6,
            share=by_part[p][1] / total if total else float("nan"),
        )
        for p in PARTS
    ]
    rows.append(
        dict(
            part="all kernels",
            kernels_per_step=sum(v[0] for v in kernels.values()) / iters,
            ms_per_step=total / iters / 1e6,
            share=1.0,
        )
    )
    wall = res.time / iters * 1e3
    wall_plain = plain.time / iters * 1e3
    la_ms = linear_algebra_ms(members)
    common.write_table(
        name,
        rows,
        ["part", "kernels_per_step", "ms_per_step", "share"],
        f"Where a sweep step's time goes: {members} members as one group on {where} "
        f"(pendulum k = {K}, EA = {EA:g} N, BDF at 1e-6, first {t1:g} s)",
        [
            f"{iters} loop iterations (the slowest member's accepted and rejected "
            f"steps); the profiled call took {res.time:.3g} s, {wall:.3g} ms per "
            f"iteration (kernel time plus launches and the loop's own "
            f"synchronisation), the same call untraced {plain.time:.3g} s, "
            f"{wall_plain:.3g} ms per iteration; first call {first.time:.3g} s, "
            "compilation included.",
            "Each kernel is attributed to the innermost named part of the step that "
            "holds its operation (`part_of`): kernels_per_step are launches per "
            "iteration, ms_per_step their summed duration per iteration.",
            f"Timed apart: the factorisation and three solves of {members} "
            f"block-tridiagonal matrices of {K} 2 x 2 blocks take {la_ms:.3g} ms "
            "(`linear_algebra_ms`).",
        ],
    )
    top = sorted(kernels.items(), key=lambda kv: -kv[1][1])[:20]
    common.write_table(
        f"{name}_kernels",
        [
            dict(
                kernel=op,
                part=part_of(names[op]),
                launches_per_step=n / iters,
                us_per_launch=ns / n / 1e3,
                share=ns / total,
                source=names[op].split("diffeqsolve))")[-1][-90:],
            )
            for op, (n, ns) in top
        ],
        ["kernel", "part", "launches_per_step", "us_per_launch", "share", "source"],
        f"The 20 kernels that take the most time, {members} members on {where}",
        ["source: the end of the operation's op_name in the optimised program."],
    )
    return rows


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--members", type=int, default=None)
    p.add_argument("--t1", type=float, default=0.05)
    p.add_argument("--name", default=None)
    p.add_argument("--keep", default=None, help="copy the trace and programs here")
    a = p.parse_args()
    main(members=a.members, t1=a.t1, name=a.name, keep=a.keep)
