"""`cpu_jit`: jaxstring's repeated compiled solves, without XLA:CPU's YNNPACK fusions.

jaxlib 0.10 hands some fusions to YNNPACK by default. In a string solve these are
small reductions over 2-4 components with a batch in front (the colour-batched JVPs
of the banded Jacobian; the members of a vmapped sweep), which YNNPACK ran several
times slower than XLA's own loop fusions on the 2-core machines:

* banded Jacobian of the displacement string, 12 coloured JVPs: 4-5x slower at
  k = 320 ... 1280 (`experiments/results/ynn_fusion.md`);
* k = 20 pendulum sweep, 64 members, one group: 4.98 s -> 2.64 s without them
  (`experiments/sweep_speed.py`).

So `fit` and `sweep`, which run one compiled solve many times, compile with the
option ``xla_cpu_experimental_ynn_fusion_type = ""`` on CPU. `simulate` keeps XLA's
defaults: with the option, the *first* execution of a compiled solve ran 3-4 ms per
step slower than later ones at k >= 640 (BDF, displacement, k = 640, 2 s: 60 s then
8.7 s; with XLA's defaults 26 s then 19 s; not understood), so a one-off run is
faster without it. A user who repeats long runs at large k sets
``XLA_FLAGS=--xla_cpu_experimental_ynn_fusion_type=`` before JAX starts (the
experiments do). It is a per-compilation option: the user's own JAX code keeps
XLA's defaults.
"""

import functools

import equinox as eqx
import jax
import jax.tree_util as jtu


CPU_COMPILER_OPTIONS = {"xla_cpu_experimental_ynn_fusion_type": ""}


def cpu_jit(fun):
    """Like `eqx.filter_jit` (arrays traced, everything else static and hashable),
    compiled with `CPU_COMPILER_OPTIONS` when every array argument is on the CPU."""

    def call(dynamic, static):
        args, items = eqx.combine(dynamic, static)
        return fun(*args, **dict(items))

    def split(args, kwargs):
        # keyword arguments as sorted (name, value) pairs: hashable when static
        return eqx.partition((args, tuple(sorted(kwargs.items()))), eqx.is_array)

    jitted = {
        True: jax.jit(call, static_argnums=1, compiler_options=CPU_COMPILER_OPTIONS),
        False: jax.jit(call, static_argnums=1),
    }

    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        dynamic, static = split(args, kwargs)
        on_cpu = all(
            d.platform == "cpu"
            for x in jtu.tree_leaves(dynamic)
            if isinstance(x, jax.Array)
            for d in x.devices()
        )
        return jitted[on_cpu](dynamic, static)

    # The CPU compilation, for inspection: `fn.lower_cpu(*args).compile().as_text()`.
    wrapper.lower_cpu = lambda *args, **kwargs: jitted[True].lower(*split(args, kwargs))
    return wrapper
