"""Variable-step, variable-order BDF (NDF), orders 1-5, as a diffrax solver.

The method is scipy's ``BDF`` (``scipy/integrate/_ivp/bdf.py``, after Shampine &
Reichelt, "The MATLAB ODE suite", SIAM J. Sci. Comput. 18 (1997), and Byrne &
Hindmarsh, ACM TOMS 1 (1975)), the class of the production codes LSODE/LSODI, DASSL
and SUNDIALS CVODE: quasi-constant step size with a backward-difference array D
(row j holds the j-th backward difference of the interpolating polynomial, scaled to
the current step h), NDF "fixed leading coefficient" formulas (kappa of Shampine &
Reichelt), simplified Newton with a stored Jacobian, the local error estimated from
the next difference, and order selection among q - 1, q, q + 1 after q + 1 equal
steps. One accepted step costs two to four vector fields and back-substitutions and,
rarely, one Jacobian (the model's own, `AbstractModel.vf_jacobian`, where it has
one, as the displacement string does; else 3 b coloured JVPs) and one factorisation
of I - c J (block cyclic reduction): O(k) for a string of k elements
(``jaxstring._linalg``).

How it fits into diffrax (static shapes, fixed-size solver state):

* The state holds D of shape (MAX_ORDER + 3, *y.shape), the step h it is scaled to,
  the order q (a traced int), the count of steps since the last change, the
  Jacobian J and the factorisation of I - c_lu J with its c_lu. Orders are handled by
  masks, never by dynamic shapes.
* diffrax gives the step as t1 - t0. When it differs from the h of D, D is rescaled
  (scipy's ``change_D``: the interpolating polynomial evaluated on the new grid).
* **The solver chooses h and q**, as scipy does, and makes diffrax's
  ``PIDController`` apply its choice: it returns a ``y_error`` whose scaled RMS norm
  r encodes the decision -- accept iff r < 1 and next step factor
  ``safety * r ** (-1 / error_order)`` = its own factor (``safety`` = 0.9,
  ``error_order`` = 2, both the PIDController defaults). ``y_error`` points along
  the true order-q error estimate; only its length is set. The PID controller's
  accepted factor is at least 1, so "accept and shrink" becomes "accept and keep h"
  (the next step then decides). This needs the solver's `rtol`, `atol` to equal the
  controller's (``simulate`` passes them so).
* The factorisation of I - c J is reused across steps (CVODE also scales the chord
  correction by 2 / (1 + c / c_lu) for c != c_lu, as done here). J is evaluated at
  the predictor and I - c J factorised afresh when the Newton iteration fails with
  the stored factorisation (scipy), or when c = h / alpha_q has changed by more than
  30 % since the last factorisation (also on the first step: `init` stores a
  placeholder with c_lu = inf). Where J is cheap the state keeps the factorisation
  only, not J: scipy and CVODE refactorise a stored J on a change of c, but every
  array of the solver state is copied through diffrax's accept/reject select and the
  while loop, and J is the largest (48 doubles a node of a 2D string; its cost:
  docs/numerics.md, "BDF"), while a fresh J costs one Jacobian evaluation on the
  rare change of c and converges at least as well. Where a Jacobian takes
  `KEEP_JACOBIAN_DIRECTIONS` JVPs or more (a mooring network with bodies, a network
  of many lines: a wide band) the state keeps J too and a change of c factorises it
  again (`keep_jacobian`); a fresh J is then taken only where the Newton iteration
  fails with the stored one. A step whose Newton iteration fails with a fresh J is
  rejected with factor 1/2. (diffrax keeps the solver state of accepted steps only,
  so a Jacobian refreshed during a rejected attempt is recomputed on the retry.) On
  the stiffest strings nearly every rejection is such a Newton failure, so after a
  rejection the step may not grow back past 90 % of the rejected one at once; that
  cap relaxes by 5 % per accepted step (fewer attempts: docs/numerics.md, "BDF").
* Where the stored factorisation keeps failing, the attempt with it is skipped. In
  displacement variables the stiff springs turn with the string and a Jacobian from
  the previous step hardly ever contracts the Newton iteration (docs/numerics.md,
  "BDF"); each failed attempt costs one or two vector fields and solves before
  the refresh. After `_SKIP_STORED_AFTER` accepted steps in a row that needed a
  refresh, the step takes a fresh Jacobian at once, and tries the stored one again
  every `_RETRY_STORED` steps (a success resets the count). Natural variables,
  whose stored Jacobian converges, never reach the count. A model that declares
  that its stiff directions turn with the state (`SolverStructure.step_jacobians`,
  the displacement string) gets `reuse_jacobian=False` from `build_solver`: a
  fresh Jacobian at every step, no attempt with a stored one, and no
  factorisation in the solver state, whose copies through the while loop and the
  accept/reject select go with it: the same steps and results in less time per
  step (docs/numerics.md, "BDF").
* Stability guard. NDF orders >= 3 are not A-stable: on the imaginary axis they
  amplify for h omega in a band (NDF3: 0.01 ... 3.4 per step, growth up to 1.12 per
  step; NDF4: 0.01 ... 6.6; NDF5: 0.7 ... 9.3; with 1 % damping the lower ends move
  to 0.44, 0.59, 0.78). A mooring line with a heavy end mass (MoorDyn's test-suite
  pendulum: EA = 1e9 N, axial modes with zeta ~ 0.01, undamped transverse modes at
  20-140 rad/s) puts such modes in the band; without a guard the grown mode makes
  the error test shrink h until the step limit ends the run (docs/numerics.md,
  "BDF"). An unresolved oscillation shows as scaled backward differences that do
  not fall with the order (on smooth strings they do): at order q >= 3 with
  |D_(q+1)| > |D_q| or |D_q| > |D_(q-1)| the order drops by one (to the A-stable
  2 at most) and h is not grown; the order is raised to 3, 4, 5 only while those
  ratios (and |D_(q+2)| / |D_(q+1)|) are <= 0.3, 0.4, 0.65: for a resolved
  oscillation the ratio is ~ h omega, and NDF5 is stable up to h omega = 0.7,
  NDF3/4 lose less than 1e-3 per step below 0.3/0.4 (the guarded BDF on the
  MoorDyn pendulum: docs/numerics.md, "BDF"). (CVODE's optional stability-limit
  detection, STALD, serves the same purpose.)
* Gradients: the Newton solve is wrapped in ``jax.lax.custom_root``, so reverse mode
  does not differentiate the iteration: the tangent system uses the exact
  Jacobian at the solution (implicit function theorem). The stored Jacobian and the
  step-size decisions carry no gradient.
"""

from typing import Any, ClassVar

import diffrax as dfx
import equinox as eqx
import jax
import jax.lax as lax
import jax.numpy as jnp
import numpy as np

from .. import _linalg
from .._jit import traced_once
from .newton import chord as newton_chord


MAX_ORDER = 5
NEWTON_MAXITER = 4
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
# Refactorise I - c J when c has moved this far (relative) from the factorised one.
_REFACTOR_CHANGE = 0.3
# After this many accepted steps in a row whose stored Jacobian failed (the Newton
# iteration needed a fresh one), go straight to a fresh Jacobian; try the stored one
# again on every _RETRY_STORED-th such step (see the module doc).
_SKIP_STORED_AFTER = 4
_RETRY_STORED = 8
# diffrax PIDController defaults that the y_error encoding relies on.
_PID_SAFETY = 0.9
_ERROR_ORDER = 2
_CAP_RELAX = 1.05
KEEP_JACOBIAN_DIRECTIONS = 40
"""`keep_jacobian="auto"` keeps J where it takes at least this many JVPs
(`_linalg.jacobian_directions`; measured: docs/numerics.md, "BDF")."""

# Stability guard: largest ratio of successive scaled backward differences to keep
# an order >= 3, and to raise the order to >= 3.
_DECAY_STAY = (1.0, 1.0, 1.0)  # orders 3, 4, 5
_DECAY_UP = (0.3, 0.4, 0.65)

# NDF coefficients (Shampine & Reichelt 1997, table 1; scipy bdf.py).
_KAPPA = np.array([0.0, -0.1850, -1 / 9, -0.0823, -0.0415, 0.0])
_GAMMA = np.concatenate([[0.0], np.cumsum(1.0 / np.arange(1, MAX_ORDER + 1))])
_ALPHA = (1 - _KAPPA) * _GAMMA
_ERROR_CONST = _KAPPA * _GAMMA + 1.0 / np.arange(1, MAX_ORDER + 2)


def _rms(x):
    return jnp.sqrt(jnp.mean(x**2))


def _change_matrix(order, factor):
    """T with D[:6] <- T @ D[:6] (scipy ``change_D``) for a traced `order`: the
    (order + 1)-block is (R U)^T, the rest identity."""
    n = MAX_ORDER + 1
    idx = jnp.arange(n)
    inside = (idx[:, None] <= order) & (idx[None, :] <= order)

    def compute_R(f):
        i = jnp.arange(1, n)[:, None].astype(jnp.result_type(f))
        j = jnp.arange(1, n)[None, :]
        m = jnp.zeros((n, n), jnp.result_type(f))
        m = m.at[1:, 1:].set((i - 1 - f * j) / i)
        m = m.at[0].set(1.0)
        return jnp.where(inside, jnp.cumprod(m, axis=0), 0.0)

    ru = compute_R(factor) @ compute_R(jnp.ones_like(factor))
    return jnp.where(inside, ru.T, jnp.eye(n, dtype=ru.dtype))


def _combine(w, D):
    """`tensordot(w, D, axes=1)` for the few (<= 8) difference rows of D, as
    broadcast multiply-adds: XLA:CPU fuses these with their neighbours, whereas a
    `dot` with a contraction of 6 is a separate kernel, as slow as several passes
    over D (docs/numerics.md, "BDF")."""
    w = jnp.asarray(w, D.dtype)
    lead = w.shape[:-1]
    out = 0.0
    for j in range(w.shape[-1]):
        out = out + w[..., j].reshape(lead + (1,) * (D.ndim - 1)) * D[j]
    return out


def _step_weights(order, factor, dtype):
    """The step's linear maps on the rows of D, as small matrices of scalars.

    With R = T D the differences rescaled from the old step to the new one (scipy's
    ``change_D``: ``_change_matrix`` on rows 0 ... MAX_ORDER, the last two rows
    unchanged) and d the Newton correction, scipy's update of an accepted step is
    ``R[q+2] = d - R[q+1]``, ``R[q+1] = d``, ``R[i] += R[i+1]`` for i = q ... 0, i.e.
    ``D_acc[i] = R[i] + ... + R[q] + d`` for i <= q. So

    * ``y_pred = w_pred . D``, ``psi = w_psi . D`` (the predictor and the history
      term, with R folded in), and
    * ``D_acc = W D + e d``, W = M T with M the update on the rows of R.

    Computing these from the stored D in one pass each (``_combine``) replaces the
    rescaled copy of D, its concatenation with the last rows, and the stacked
    reverse cumulative sum: on XLA:CPU those concatenations are separate passes
    over D (docs/numerics.md, "BDF").
    """
    n = MAX_ORDER + 3
    T6 = _change_matrix(order, factor)
    T = jnp.eye(n, dtype=dtype).at[: MAX_ORDER + 1, : MAX_ORDER + 1].set(T6)
    i = jnp.arange(n)[:, None]
    j = jnp.arange(n)[None, :]
    M = jnp.where((i <= order) & (j >= i) & (j <= order), 1.0, 0.0)
    M = M + jnp.where((i == order + 2) & (j == order + 1), -1.0, 0.0)
    M = M + jnp.where((i > order + 2) & (i == j), 1.0, 0.0)
    e = jnp.where(jnp.arange(n) <= order + 2, 1.0, 0.0).astype(dtype)
    pred = jnp.where(jnp.arange(n) <= order, 1.0, 0.0).astype(dtype)
    gam = jnp.asarray(np.concatenate([_GAMMA, [0.0, 0.0]]), dtype)
    gam = jnp.where((jnp.arange(n) >= 1) & (jnp.arange(n) <= order), gam, 0.0)
    alpha = jnp.asarray(_ALPHA, dtype)[order]
    return M.astype(dtype) @ T, e, pred @ T, (gam / alpha) @ T


class BDFState(eqx.Module):
    D: jax.Array  # (MAX_ORDER + 3, *y.shape) backward differences, scaled to h
    h: jax.Array  # the step D is scaled to
    order: jax.Array  # int, 1 ... max_order
    n_equal: jax.Array  # steps since the last change of h or order
    lu: Any  # factorisation of I - c_lu J (J at an earlier predictor), no gradient
    c_lu: jax.Array
    jac: Any  # that J (`keep_jacobian`), else None
    h_next: jax.Array  # the step this solver asked for next
    h_cap: jax.Array  # growth cap after a rejection (see `step`)
    n_refresh: jax.Array  # accepted steps in a row whose stored Jacobian failed


class BDFInterpolation(dfx.AbstractLocalInterpolation):
    """Dense output on one step: the order-q interpolating polynomial of D."""

    t0: jax.Array
    t1: jax.Array
    D: jax.Array  # (MAX_ORDER + 3, *y.shape), rows above `order` are not used
    order: jax.Array

    def evaluate(self, t0, t1=None, left: bool = True):
        del left
        if t1 is not None:
            return self.evaluate(t1) - self.evaluate(t0)
        h = self.t1 - self.t0
        m = jnp.arange(MAX_ORDER)
        x = (t0 - (self.t1 - m * h)) / ((m + 1) * h)
        p = jnp.where(m + 1 <= self.order, jnp.cumprod(x), 0.0)
        return self.D[0] + _combine(p, self.D[1 : MAX_ORDER + 1])


class _VF(eqx.Module):
    """f(y; (t, terms, args)) -- a pytree-only callable for structure detection."""

    def __call__(self, y, a):
        t, terms, args = a
        return terms.vf(t, y, args)


class BDF(dfx.AbstractAdaptiveSolver):
    """Variable-order (1-5), variable-step BDF/NDF with a reused Jacobian
    (scipy ``BDF`` / LSODE / CVODE class), for stiff ODEs.

    **Arguments:**

    - `rtol`, `atol`: the error tolerances; must equal those of the
      `diffrax.PIDController` that drives it (default safety 0.9). They also set the
      Newton tolerance (scipy's `max(10 eps / rtol, min(0.03, rtol ** 0.5))`).
    - `max_order`: highest order, 1 ... 5.
    - `linear_solver`: `"auto"` (banded for strings and chains, dense otherwise),
      `"dense"` or `"banded"`.
    - `reuse_jacobian`: keep the factorisation of I - c J across steps (default
      True). False takes a fresh Jacobian and factorisation at every step and
      carries none in the solver state: for models whose stiff directions turn
      with the state, where a stored Jacobian does not contract the Newton
      iteration (the displacement string; `build_solver` sets it from
      `SolverStructure.step_jacobians`).
    - `keep_jacobian`: keep J itself too, and refactorise it when c changes,
      taking a fresh J only where the Newton iteration fails with the stored one
      (CVODE's way), or not (a change of c takes a fresh J); `"auto"` (default):
      keep it where a Jacobian takes `KEEP_JACOBIAN_DIRECTIONS` JVPs or more.
    - `differentiable`: False for a solve that nothing differentiates (a saved
      program, a sweep's): the Newton solve is then not wrapped in `custom_root`,
      which traces the derivative's linearisation and solve with every step,
      derivative or not. The same values either way.

    For ODE terms only (`diffrax.ODETerm`); the state is one array. Use it with
    `diffrax.PIDController(rtol=rtol, atol=atol)` (the solver picks h and the order
    and the controller applies them; see the module docstring).
    """

    rtol: Any = 1e-6
    atol: Any = 1e-6
    max_order: int = eqx.field(static=True, default=MAX_ORDER)
    linear_solver: str = eqx.field(static=True, default="auto")
    reuse_jacobian: bool = eqx.field(static=True, default=True)
    keep_jacobian: bool | str = eqx.field(static=True, default="auto")
    differentiable: bool = eqx.field(static=True, default=True)
    term_structure: ClassVar = dfx.AbstractTerm
    interpolation_cls: ClassVar = BDFInterpolation

    def __check_init__(self):
        if not (isinstance(self.max_order, int) and 1 <= self.max_order <= MAX_ORDER):
            raise ValueError(
                f"`max_order` must be an integer in [1, {MAX_ORDER}]; "
                f"got {self.max_order!r}."
            )
        if self.linear_solver not in ("auto", "dense", "banded"):
            raise ValueError(
                "`linear_solver` must be one of 'auto', 'dense', 'banded'; "
                f"got {self.linear_solver!r}."
            )
        if self.keep_jacobian not in ("auto", True, False):
            raise ValueError(
                "`keep_jacobian` must be 'auto', True or False; "
                f"got {self.keep_jacobian!r}."
            )

    def order(self, terms):
        return self.max_order

    def error_order(self, terms):
        # Not the method's order: the exponent of the y_error encoding (and scipy's
        # order-1 initial step, which diffrax's PIDController.init derives from it).
        return _ERROR_ORDER

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)

    def _width(self, terms, t, y, args):
        return _linalg.choose_structure(_VF(), y, (t, terms, args), self.linear_solver)

    def _keeps(self, width, y):
        """Whether the state keeps J (`keep_jacobian`) for this structure."""
        if not self.reuse_jacobian:
            return False
        if self.keep_jacobian == "auto":
            return _linalg.jacobian_directions(width, y.shape) >= (
                KEEP_JACOBIAN_DIRECTIONS
            )
        return bool(self.keep_jacobian)

    def _jacobian(self, terms, t, y, args, width, shape_only=False):
        """J(t, y); `shape_only`: for its structure only (`jax.eval_shape`), the
        identity's Jacobian, of the same structure, without the vector field's
        JVPs."""
        if width == 1:
            jac = _linalg.model_jacobian(terms, t, y, args)
            if jac is not None:
                return lax.stop_gradient(jac)
        fn = (lambda u: u) if shape_only else (lambda u: terms.vf(t, u, args))
        _, lin = jax.linearize(fn, y)
        so = _linalg.declared_second_order(_VF(), y, (t, terms, args))
        seq = _linalg.declared_sequential(_VF(), y, (t, terms, args))
        return lax.stop_gradient(_linalg.jacobian(fn, y, width, lin, so, seq))

    def _start(self, terms, t0, h, y0, args):
        f0 = terms.vf(t0, y0, args)
        D = jnp.zeros((MAX_ORDER + 3,) + y0.shape, y0.dtype)
        return D.at[0].set(y0).at[1].set(f0 * h)

    def init(self, terms, t0, t1, y0, args):
        h = jnp.asarray(t1 - t0, dtype=y0.dtype)
        width = self._width(terms, t0, y0, args)
        # No factorisation here: a placeholder of the factorisation's structure with
        # c_lu = inf, which the first step sees as a changed c and so factorises
        # afresh at its predictor. (One Jacobian and factorisation fewer in the
        # compiled program: each is a few hundred XLA operations.)
        structure = lambda: _linalg.factor(
            self._jacobian(terms, t0, y0, args, width, True).scale_shift(1.0, -h)
        )
        lu = jac = None
        zeros = lambda tree: jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), tree)
        if self.reuse_jacobian:
            lu = zeros(jax.eval_shape(structure))
            if self._keeps(width, y0):
                jac = zeros(
                    jax.eval_shape(
                        lambda: self._jacobian(terms, t0, y0, args, width, True)
                    )
                )
        return BDFState(
            D=self._start(terms, t0, h, y0, args),
            h=h,
            order=jnp.array(1, jnp.int32),
            n_equal=jnp.array(0, jnp.int32),
            lu=lu,
            c_lu=jnp.asarray(jnp.inf, h.dtype),
            jac=jac,
            h_next=h,
            h_cap=jnp.asarray(jnp.inf, h.dtype),
            n_refresh=jnp.array(0, jnp.int32),
        )

    @traced_once
    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        st = solver_state
        dtype = y0.dtype
        h = jnp.asarray(t1 - t0, dtype=dtype)
        order = st.order
        D = st.D
        if made_jump is not False:
            # Restart at order 1 after a discontinuity.
            D = jnp.where(made_jump, self._start(terms, t0, st.h, y0, args), D)
            order = jnp.where(made_jump, 1, order)
        rtol, atol = self.rtol, self.atol
        newton_tol = jnp.maximum(
            10 * jnp.finfo(dtype).eps / rtol, jnp.minimum(0.03, jnp.sqrt(rtol))
        )

        # Rescale D from st.h to h (exact for the interpolating polynomial); the
        # rescaling is folded into the weights of every use of D (`_step_weights`).
        factor = h / st.h
        W_acc, e_acc, w_pred, w_psi = _step_weights(order, factor, dtype)
        same_h = jnp.abs(factor - 1) < 1e-6
        n_equal = jnp.where(same_h, st.n_equal, 0)
        # A step shorter than the one asked for follows a rejection (nearly always a
        # Newton failure on the stiff strings): do not grow back past 90 % of the
        # failed step at once; the cap relaxes by _CAP_RELAX per accepted step.
        # (diffrax discards the solver state of rejected steps, so the failure is
        # recognised here.) The last step, clipped to t1, looks the same: harmless.
        rejected_before = h < st.h_next * (1 - 1e-6)
        h_cap = jnp.where(rejected_before, 0.9 * st.h_next, st.h_cap * _CAP_RELAX)

        alpha = jnp.asarray(_ALPHA, dtype)[order]
        y_pred = _combine(w_pred, D)
        psi = _combine(w_psi, D)
        c = h / alpha
        scale = atol + rtol * jnp.abs(y_pred)
        width = self._width(terms, t1, y_pred, args)
        second_order = _linalg.declared_second_order(_VF(), y0, (t1, terms, args))
        sequential = _linalg.declared_sequential(_VF(), y0, (t1, terms, args))

        def residual(d):
            return c * terms.vf(t1, y_pred + d, args) - psi - d

        def new_jacobian():
            return self._jacobian(terms, t1, y_pred, args, width)

        def fresh_factor(jac=None):
            jac = new_jacobian() if jac is None else jac
            return _linalg.factor(jac.scale_shift(1.0, -c))

        def newton(fn, d0, lu, c_lu):
            corr = 2.0 / (1.0 + c / c_lu)  # CVODE's chord scaling for c != c_lu
            # scipy's prediction counts the current update as one still to come:
            # a horizon of NEWTON_MAXITER + 1 updates.
            return newton_chord(
                fn,
                lambda r: -corr * lu.solve(r),
                d0,
                lambda d, dd, d_new: _rms(dd / scale),
                newton_tol,
                NEWTON_MAXITER,
                horizon=NEWTON_MAXITER + 1,
            )

        def with_aux(d, aux_tree):
            # custom_root gives its aux output tangents of the aux dtype, which
            # JAX rejects for integers (float0 expected): pass them as floats.
            leaves, treedef = jax.tree_util.tree_flatten(aux_tree)
            aux_types.append((treedef, [x.dtype for x in leaves]))
            return d, [x.astype(dtype) for x in leaves]

        def solve_fresh(fn, d0):
            # A fresh factorisation at every step, none stored (`reuse_jacobian`).
            lu = fresh_factor()
            d, conv, k = newton(fn, d0, lu, c)
            return with_aux(d, (conv, k, None, c, None, jnp.array(False)))

        def solve(fn, d0):
            # Skip the stored Jacobian where it has kept failing (module doc).
            skip = (st.n_refresh >= _SKIP_STORED_AFTER) & (
                st.n_refresh % _RETRY_STORED != 0
            )
            # The stored factorisation, or a fresh one if c moved by more than 30 %
            # (with `keep_jacobian`: the stored J factorised again).
            stale_c = (jnp.abs(c / st.c_lu - 1) > _REFACTOR_CHANGE) & ~skip
            lu0 = lax.stop_gradient(st.lu)
            c_lu0 = lax.stop_gradient(st.c_lu)
            jac0 = lax.stop_gradient(st.jac)
            keep = self._keeps(width, y0)

            # First the stored factorisation, unless it is being skipped or c has
            # changed; then, if that did not converge, a fresh one: two attempts
            # of one loop, so that the program holds one factorisation and one
            # Newton iteration, not one per case (a Jacobian and a factorisation
            # are a few hundred XLA operations, an iteration a vector field and a
            # solve).
            def attempt(carry):
                n, _, _, _, lu, c_lu, jac, stored_ok = carry
                fresh = n > 0
                if keep:
                    jac = lax.cond(fresh, new_jacobian, lambda: jac)
                    redo = fresh | stale_c
                    lu = lax.cond(redo, lambda: fresh_factor(jac), lambda: lu)
                else:
                    redo = fresh
                    lu = lax.cond(fresh, fresh_factor, lambda: lu)
                c_lu = jnp.where(redo, c, c_lu)
                d, conv, k = newton(fn, d0, lu, c_lu)
                return n + 1, d, conv, k, lu, c_lu, jac, stored_ok | (~fresh & conv)

            def again(carry):
                n, _, conv = carry[:3]
                return (n == 0) | ((n == 1) & ~conv)

            # with a stored J, a change of c refactorises it; the first step
            # (c_lu = inf, J a placeholder) takes a fresh one
            first = jnp.where(skip | (jnp.isinf(st.c_lu) if keep else stale_c), 1, 0)
            start = (first, d0, jnp.array(False), jnp.array(0, jnp.int32))
            start += (lu0, c_lu0, jac0, jnp.array(False))
            out = lax.while_loop(again, attempt, start)
            _, d, conv, k, lu, c_lu, jac, stored_ok = out
            refreshed = ~stored_ok if keep else ~stored_ok & ~stale_c
            return with_aux(d, (conv, k, lu, c_lu, jac, refreshed))

        def tangent_solve(g, b):
            # g(v) = (c J - I) v at the solution; exact solve (derivative passes only).
            # custom_root traces this with every step of a differentiable solver,
            # gradient or not: the reduced second-order factorisation (2 x 2
            # closed-form blocks for a string) also keeps that tracing cheap.
            mat = _linalg.jacobian(g, b, width, g, second_order, sequential)
            return _linalg.factor(mat).solve(b)

        aux_types = []
        newton_solve = solve if self.reuse_jacobian else solve_fresh
        if self.differentiable:
            d, aux = lax.custom_root(
                residual, jnp.zeros_like(y0), newton_solve, tangent_solve, has_aux=True
            )
        else:
            d, aux = newton_solve(residual, jnp.zeros_like(y0))
        treedef, types = aux_types[-1]
        aux = [lax.stop_gradient(x).astype(t) for x, t in zip(aux, types)]
        conv, n_iter, lu, c_lu, jac, refreshed = jax.tree_util.tree_unflatten(
            treedef, aux
        )
        y_new = y_pred + d
        finite = jnp.all(jnp.isfinite(y_new))
        conv = conv & finite
        y_new_safe = jnp.where(finite, y_new, y0)

        # Local error estimate (order q) and acceptance.
        ec = jnp.asarray(_ERROR_CONST, dtype)
        scale_new = atol + rtol * jnp.abs(lax.stop_gradient(y_new_safe))
        err = lax.stop_gradient(ec[order] * d)
        err_norm = _rms(err / scale_new)
        accept = conv & (err_norm <= 1)
        safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
        f_reject = jnp.where(
            conv,
            jnp.maximum(MIN_FACTOR, safety * err_norm ** (-1.0 / (order + 1))),
            0.5,
        )

        # Accepted: update the differences (scipy: D[q+2] = d - D[q+1], D[q+1] = d,
        # D[i] += D[i+1] for i = q ... 0, on the rescaled D; `_step_weights`).
        D_acc = _combine(W_acc, D) + e_acc.reshape((-1,) + (1,) * d.ndim) * d
        n_acc = n_equal + 1

        # Order selection after q + 1 equal steps (scipy), from the scaled RMS norms
        # of the four rows of D_acc it reads, q - 1 ... q + 2 (one reduction).
        ecs = lax.stop_gradient(D_acc)
        lo = order - 1
        near = lax.dynamic_slice_in_dim(ecs, lo, 4, axis=0)
        rms_near = jnp.sqrt(
            jnp.mean((near / scale_new) ** 2, axis=tuple(range(1, ecs.ndim)))
        )
        # The scaled RMS norm of row j of D_acc, for q - 1 <= j <= q + 2, j >= 1.
        n_of = lambda j: jnp.take(rms_near, jnp.maximum(j, 1) - lo)
        err_m = ec[order - 1] * n_of(order)
        err_p = ec[jnp.minimum(order + 1, MAX_ORDER)] * n_of(order + 2)
        err_m = jnp.where(order > 1, err_m, jnp.inf)
        err_p = jnp.where(order < self.max_order, err_p, jnp.inf)
        norms = jnp.stack([err_m, err_norm, err_p])
        expo = -1.0 / (order + jnp.arange(3)).astype(dtype)
        with jax.numpy_dtype_promotion("standard"):
            factors = jnp.where(norms == 0, jnp.inf, norms**expo)
        factors = jnp.where(jnp.isnan(factors), 0.0, factors)
        delta = jnp.argmax(factors) - 1
        select = n_acc >= order + 1
        # Stability guard (see module doc): orders >= 3 are not A-stable, and on a
        # lightly damped stiff oscillation (h omega in their unstable band) they
        # amplify it. Such a mode shows as backward differences that stop falling
        # with the order. Then drop the order by one (down to the A-stable 2) at
        # once, and raise it to >= 3 only while the differences fall clearly.
        ratio_q = jnp.maximum(
            n_of(order + 1) / n_of(order), n_of(order) / n_of(order - 1)
        )
        ratio_up = jnp.maximum(n_of(order + 2) / n_of(order + 1), ratio_q)
        lim = lambda table, q: jnp.asarray(table, dtype)[jnp.clip(q - 3, 0, 2)]
        unstable = (order >= 3) & ~(ratio_q <= lim(_DECAY_STAY, order))
        up_ok = (order + 1 < 3) | (ratio_up <= lim(_DECAY_UP, order + 1))
        delta = jnp.where((delta > 0) & ~up_ok, 0, delta)
        new_order = jnp.where(select, order + delta, order)
        new_order = jnp.where(unstable, order - 1, new_order).astype(jnp.int32)
        f_sel = jnp.take(factors, delta + 1)  # the chosen order's factor
        f_accept = jnp.where(select, jnp.minimum(MAX_FACTOR, safety * f_sel), 1.0)
        f_accept = jnp.where(unstable, jnp.minimum(f_accept, 1.0), f_accept)
        n_acc = jnp.where(select | unstable, 0, n_acc)
        f_accept = jnp.minimum(f_accept, jnp.maximum(h_cap / h, 1.0))

        # Encode the decision as the PID controller's scaled error r (module doc).
        r_accept = jnp.minimum((_PID_SAFETY / f_accept) ** _ERROR_ORDER, _PID_SAFETY**2)
        r_reject = jnp.maximum((_PID_SAFETY / f_reject) ** _ERROR_ORDER, 1.01)
        r = jnp.where(accept, r_accept, r_reject)
        # y1 is the Newton solution whenever there is one (a step rejected by the error
        # test is retried by the controller; a fixed-step controller keeps it).
        y1 = jnp.where(conv, y_new, y0)
        y1_sg = lax.stop_gradient(y1)
        pid_scale = atol + rtol * jnp.maximum(jnp.abs(y0), jnp.abs(y1_sg))
        e_norm = _rms(err / pid_scale)
        use_err = accept & (e_norm > 0) & jnp.isfinite(e_norm)
        y_error = jnp.where(
            use_err, err * (r / jnp.where(use_err, e_norm, 1.0)), r * pid_scale
        )
        y_error = lax.stop_gradient(y_error)

        new_state = BDFState(
            D=D_acc,
            h=h,
            order=new_order,
            n_equal=n_acc.astype(jnp.int32),
            lu=lu,
            c_lu=c_lu,
            jac=jac,
            h_next=h * jnp.maximum(f_accept, 1.0),
            h_cap=h_cap,
            n_refresh=jnp.where(refreshed, st.n_refresh + 1, 0).astype(jnp.int32),
        )
        dense_info = dict(D=D_acc, order=order)
        # A failed Newton iteration is an error only if the controller keeps the step
        # (diffrax ignores the result of rejected steps).
        result = dfx.RESULTS.where(
            conv, dfx.RESULTS.successful, dfx.RESULTS.nonlinear_divergence
        )
        return y1, y_error, dense_info, new_state, result
