"""Rodas5P: a stiffly accurate Rosenbrock method of order 5(4) as a diffrax solver.

One Jacobian and one factorisation of ``I / (h gamma) - J`` per step, then eight
linear solves -- no Newton iteration, so no convergence failure can reject a step;
only the error test does. With the banded Jacobian of ``jaxstring._linalg`` (3 B
JVPs, block cyclic reduction) a step costs O(k) for a string of k elements.

Method: G. Steinebach, "Construction of Rosenbrock-Wanner method Rodas5P and
numerical benchmarks within the Julia Differential Equations package", BIT Numerical
Mathematics 63 (2023). Coefficients in the W-transformed form of Hairer & Wanner
(Solving ODEs II, section IV.7), as tabulated in OrdinaryDiffEq.jl
(src/tableaus/rosenbrock_tableaus.jl, ``Rodas5PTableau``):

    (I / (h gamma) - J) k_i = f(t0 + c_i h, y0 + sum_j a_ij k_j)
                              + sum_j (C_ij / h) k_j + h d_i df/dt,

stages 7 and 8 at y0 + sum_j a_6j k_j + k_6 (+ k_7); y1 = that + k_7 + k_8 and the
error estimate is k_8 (embedded order 4). Dense output of order 4:
y(t0 + s h) = (1 - s) y0 + s (y1 + (1 - s)(q1 + s (q2 + s q3))), q = H k.
The Jacobian must be exact (it is: autodiff, banded or dense).
"""

from typing import ClassVar

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _linalg
from .._jit import traced_once
from .fixed_step import OneStepODESolver


_GAMMA = 0.21193756319429014
_A = np.zeros((8, 8))
_A[1, 0] = 3.0
_A[2, :2] = [2.849394379747939, 0.45842242204463923]
_A[3, :3] = [-6.954028509809101, 2.489845061869568, -10.358996098473584]
_A[4, :4] = [
    2.8029986275628964,
    0.5072464736228206,
    -0.3988312541770524,
    -0.04721187230404641,
]
_A[5, :5] = [
    -7.502846399306121,
    2.561846144803919,
    -11.627539656261098,
    -0.18268767659942256,
    0.030198172008377946,
]
_A[6, :5] = _A[5, :5]
_A[6, 5] = 1.0
_A[7, :6] = _A[6, :6]
_A[7, 6] = 1.0
_B = np.concatenate([_A[7, :7], [1.0]])
_C = np.zeros((8, 8))
_C[1, 0] = -14.155112264123755
_C[2, :2] = [-17.97296035885952, -2.859693295451294]
_C[3, :3] = [147.12150275711716, -1.41221402718213, 71.68940251302358]
_C[4, :4] = [
    165.43517024871676,
    -0.4592823456491126,
    42.90938336958603,
    -5.961986721573306,
]
_C[5, :5] = [
    24.854864614690072,
    -3.0009227002832186,
    47.4931110020768,
    5.5814197821558125,
    -0.6610691825249471,
]
_C[6, :6] = [
    30.91273214028599,
    -3.1208243349937974,
    77.79954646070892,
    34.28646028294783,
    -19.097331116725623,
    -28.087943162872662,
]
_C[7, :7] = [
    37.80277123390563,
    -3.2571969029072276,
    112.26918849496327,
    66.9347231244047,
    -40.06618937091002,
    -54.66780262877968,
    -9.48861652309627,
]
_c = np.array(
    [
        0.0,
        0.6358126895828704,
        0.4095798393397535,
        0.9769306725060716,
        0.4288403609558664,
        1.0,
        1.0,
        1.0,
    ]
)
_d = np.array(
    [
        0.21193756319429014,
        -0.42387512638858027,
        -0.3384627126235924,
        1.8046452872882734,
        2.325825639765069,
        0.0,
        0.0,
        0.0,
    ]
)
_H = np.array(
    [
        [
            25.948786856663858,
            -2.5579724845846235,
            10.433815404888879,
            -2.3679251022685204,
            0.524948541321073,
            1.1241088310450404,
            0.4272876194431874,
            -0.17202221070155493,
        ],
        [
            -9.91568850695171,
            -0.9689944594115154,
            3.0438037242978453,
            -24.495224566215796,
            20.176138334709044,
            15.98066361424651,
            -6.789040303419874,
            -6.710236069923372,
        ],
        [
            11.419903575922262,
            2.8879645146136994,
            72.92137995996029,
            80.12511834622643,
            -52.072871366152654,
            -59.78993625266729,
            -0.15582684282751913,
            4.883087185713722,
        ],
    ]
)


class RodasInterpolation(dfx.AbstractLocalInterpolation):
    """Order-4 dense output of Rodas5P on one step."""

    t0: jax.Array
    t1: jax.Array
    y0: jax.Array
    y1: jax.Array
    q: jax.Array  # (3, *y.shape)

    def evaluate(self, t0, t1=None, left: bool = True):
        del left
        if t1 is not None:
            return self.evaluate(t1) - self.evaluate(t0)
        s = (t0 - self.t0) / (self.t1 - self.t0)
        s1 = 1 - s
        q1, q2, q3 = self.q[0], self.q[1], self.q[2]
        return s1 * self.y0 + s * (self.y1 + s1 * (q1 + s * (q2 + s * q3)))


class _VF(eqx.Module):
    """f(y; (t, terms, args)) -- a pytree-only callable for structure detection."""

    def __call__(self, y, a):
        t, terms, args = a
        return terms.vf(t, y, args)


class Rodas5P(OneStepODESolver, dfx.AbstractAdaptiveSolver):
    """Rodas5P (Steinebach 2023): Rosenbrock-Wanner, order 5(4), stiffly accurate,
    one Jacobian and one factorisation per step.

    **Arguments:**

    - `linear_solver`: `"auto"` (banded for strings and chains, dense otherwise),
      `"dense"` or `"banded"`.

    For ODE terms only (`diffrax.ODETerm`); the state is one array.
    """

    linear_solver: str = eqx.field(static=True, default="auto")
    interpolation_cls: ClassVar = RodasInterpolation

    def order(self, terms):
        return 5

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        del solver_state, made_jump
        h = t1 - t0
        vf = _VF()
        width = _linalg.choose_structure(vf, y0, (t0, terms, args), self.linear_solver)
        jac = _linalg.model_jacobian(terms, t0, y0, args) if width == 1 else None
        if jac is None:
            f0, lin = jax.linearize(lambda y: terms.vf(t0, y, args), y0)
            so = _linalg.declared_second_order(vf, y0, (t0, terms, args))
            seq = _linalg.declared_sequential(vf, y0, (t0, terms, args))
            fn = lambda y: terms.vf(t0, y, args)
            jac = _linalg.jacobian(fn, y0, width, lin, so, seq)
        else:
            f0 = terms.vf(t0, y0, args)
        # df/dt by one JVP in t (zero for autonomous scenes, and cheap).
        _, dT = jax.jvp(lambda t: terms.vf(t, y0, args), (t0,), (jnp.ones_like(t0),))
        fac = _linalg.factor(jac.scale_shift(1.0 / (h * _GAMMA), -1.0))
        # Stage 1 from f0; stages 2-8 in one loop over the tableau's rows, so that
        # the program holds one vector field and one solve, not seven and eight.
        k0 = fac.solve(f0 + (h * _d[0]) * dT)
        ks = jnp.zeros((8,) + k0.shape, k0.dtype).at[0].set(k0)
        A, C, c, d = (jnp.asarray(x) for x in (_A, _C, _c, _d))

        def stage(i, ks):
            yi = y0 + jnp.tensordot(A[i], ks, axes=1)
            fi = terms.vf(t0 + c[i] * h, yi, args)
            rhs = fi + jnp.tensordot(C[i], ks, axes=1) / h + (h * d[i]) * dT
            return ks.at[i].set(fac.solve(rhs))

        ks = jax.lax.fori_loop(1, 8, stage, ks)
        y1 = y0 + jnp.tensordot(jnp.asarray(_B), ks, axes=1)
        y_error = ks[7]
        q = jnp.tensordot(jnp.asarray(_H), ks, axes=1)
        finite = jnp.all(jnp.isfinite(y1)) & jnp.all(jnp.isfinite(y_error))
        y_error = jnp.where(finite, y_error, jnp.inf)
        dense_info = dict(y0=y0, y1=y1, q=q)
        return y1, y_error, dense_info, None, dfx.RESULTS.successful
