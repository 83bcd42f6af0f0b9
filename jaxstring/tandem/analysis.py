"""Equilibria, linear stability and limit cycles of the vessel models.

* `find_equilibria(scene)`: all static equilibria from a grid of starts (spec S1),
  solved by Newton's method over the batch of starts, de-duplicated and
  classified by the eigenvalues of the `jacfwd` Jacobian (spec S2).
* `solve_equilibrium(scene, q0)`: one equilibrium from one start (continuation).
* `stability(scene, y)`: eigenvalues and class of one equilibrium.
* `measure_limit_cycle(traj, t_from)`: period, yaw amplitudes, span and tension
  of a fishtailing run (spec S3a).
* `hopf_sweep(...)`: leading eigenvalue of the aligned equilibrium over the astern
  pull F_ast and the Hopf point where it crosses the imaginary axis (spec S3b).
* `pitchfork_sweep(...)`: the same for the FPSO alone over the turret position
  (spec S0).

Equilibrium unknowns are `q = (x1, y1, psi1, x2, y2, psi2)` (positions in units
of `LSCALE`) with zero velocities; the residual is the body loads (force/`FSCALE`,
moment/(`FSCALE` `LSCALE`)), which vanish exactly where the accelerations do.
"""

import dataclasses
import inspect
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _programs
from .._arrays import host_op
from .._blas import single_blas_thread
from .._jit import cpu_jit
from .._lazy import optimistix as optx
from .._scene import Scene
from .vessels import Hawser, Tandem, hull_clearance, rot, wrap


LSCALE = 100.0  # m
FSCALE = 1.0e5  # N

STABLE, SADDLE, OSCILLATORY = "stable", "saddle", "oscillatory unstable"


def _n(scene):
    return scene.model.n_vessels


def state_from_q(q, n):
    """Full state (zero velocities) from the equilibrium unknowns."""
    q = q.reshape(n, 3)
    eta = jnp.concatenate([q[:, :2] * LSCALE, q[:, 2:]], axis=1)
    return jnp.concatenate([eta, jnp.zeros_like(eta)], axis=1).reshape(-1)


def q_from_state(y, n):
    eta = y.reshape(n, 6)[:, :3]
    return jnp.concatenate([eta[:, :2] / LSCALE, eta[:, 2:]], axis=1).reshape(-1)


def _load_scale(scene):
    """Per equilibrium equation: body mass over the load scale, so that the scaled
    residual is the body load (at zero velocity nu_dot = M^{-1} tau exactly: the
    Coriolis terms vanish)."""
    h = scene.model.hulls()
    m = jnp.stack([h.m11, h.m22, h.m66], axis=1)
    return (m / jnp.array([FSCALE, FSCALE, FSCALE * LSCALE])).reshape(-1)


def residual(q, scene: Scene):
    """Scaled body loads at the zero-velocity state of `q` (zero at equilibrium)."""
    n = _n(scene)
    f = scene.vector_field(0.0, state_from_q(q, n)).reshape(n, 6)[:, 3:]
    return f.reshape(-1) * _load_scale(scene)


def _linearised(scene, q, full):
    """The residual at `q` and its Jacobian d residual / dq from one `jacfwd` of
    the vector field at the zero-velocity state of `q` (the residual is its
    acceleration rows, the unknowns its position columns, both scaled); `full`:
    also the vector field's whole Jacobian dF/dX there (its velocity columns too)."""
    n = _n(scene)
    vf = lambda y: scene.vector_field(0.0, y)  # noqa: E731
    y = state_from_q(q, n)
    dy_dq = jnp.tile(jnp.array([LSCALE, LSCALE, 1.0]), n)
    w = _load_scale(scene)
    if full:
        jac, f = jax.jacfwd(lambda y: (lambda f: (f, f))(vf(y)), has_aux=True)(y)
        dpos = jac.reshape(n, 6, n, 6)[:, :, :, :3].reshape(6 * n, 3 * n) * dy_dq
    else:
        # the position columns only: six directions in place of twelve
        pos = (6 * jnp.arange(n)[:, None] + jnp.arange(3)).reshape(-1)
        tangents = jnp.zeros((3 * n, 6 * n)).at[jnp.arange(3 * n), pos].set(dy_dq)
        f, dpos = jax.vmap(lambda t: jax.jvp(vf, (y,), (t,)), out_axes=(None, 1))(
            tangents
        )
        jac = None
    r = f.reshape(n, 6)[:, 3:].reshape(-1) * w
    block = dpos.reshape(n, 6, 3 * n)[:, 3:].reshape(3 * n, 3 * n)
    return r, block * w[:, None], jac


# Equilibrium solvers (static choice). Newton jumps far from its start and finds
# the most roots; the trust-region least-squares solvers (Dogleg is the
# optimistix analogue of MINPACK's hybrd) stay nearer their starts. Their
# Cauchy termination test is often not met once the residual is at round-off
# (rejected steps near the root), so for them a solve counts as converged by its
# residual alone.
_METHODS = {
    "newton": ("Newton", True),
    "dogleg": ("Dogleg", False),
    "lm": ("LevenbergMarquardt", False),
}


def _check_method(method):
    if method not in _METHODS:
        raise ValueError(f"`method` must be one of {sorted(_METHODS)}; got {method!r}.")


def _newton_batch(scene, q0s, rtol, atol, max_steps, jacobian=None):
    """Newton's method from every start `q0s` (shape `(B, 3 n)`) at once: the
    iterates and the termination of `optimistix.Newton` (Cauchy test: the step
    within `atol + rtol |q|` and the residual within `atol`, both in the max norm;
    a non-finite iterate or step fails the start), written over the batch.

    The loop runs on the stacked starts, each frozen once it has stopped, rather
    than under `vmap`: a vmapped `while_loop` is traced again to batch its body.
    A last pass after the final step evaluates the residual at the solutions.

    `jacobian`: where the vector field's whole Jacobian dF/dX at the solutions
    comes from (for their stability). "loop": every pass takes it (the Newton
    matrix is its position columns), the last pass at the solutions: one
    linearisation in the program, the smaller compilation (one scene). "after":
    the passes take the position columns only and one more linearisation takes
    it at the solutions: two in the program, the faster run (a batch of scenes;
    docs/performance.md, "The README's examples"). None: not needed.

    Returns (solutions, converged mask, max |residual|, dF/dX at each solution
    or None)."""
    lin = jax.vmap(lambda q: _linearised(scene, q, jacobian == "loop"))

    def body(carry):
        q, k, done, failed = carry[:4]
        active = ~(done | failed) & (k < max_steps)
        f, jac, jac_y = lin(q)
        step = jnp.linalg.solve(jac, f[..., None])[..., 0]
        small_step = jnp.max(jnp.abs(step) / (atol + rtol * jnp.abs(q)), axis=1) < 1
        small_f = jnp.max(jnp.abs(f), axis=1) < atol
        bad = ~(jnp.all(jnp.isfinite(step), axis=1) & jnp.all(jnp.isfinite(q), axis=1))
        q = jnp.where(active[:, None], q - step, q)
        done = done | (active & ~bad & small_step & small_f)
        failed = failed | (active & bad)
        return q, k + 1, done, failed, jnp.any(active), f, jac_y

    def cond(carry):
        return carry[4]

    b, m = q0s.shape
    none = jnp.zeros(b, dtype=bool)
    jac_y = jnp.zeros((b, 2 * m, 2 * m)) if jacobian == "loop" else None
    carry = (q0s, 0, none, none, True, jnp.zeros((b, m)), jac_y)
    q, _, done, _, _, f, jac_y = jax.lax.while_loop(cond, body, carry)
    if jacobian == "after":
        jac_y = jax.vmap(lambda q: _linearised(scene, q, True)[2])(q)
    return q, done, jnp.max(jnp.abs(f), axis=1), jac_y


def _solve_batch_body(scene, q0s, rtol, atol, max_steps, method="newton"):
    if method == "newton":
        return _newton_batch(scene, q0s, rtol, atol, max_steps)[:3]
    name, use_flag = _METHODS[method]
    cls = getattr(optx, name)
    solver = cls(rtol=rtol, atol=atol)

    def one(q0):
        sol = optx.root_find(
            residual, solver, q0, args=scene, max_steps=max_steps, throw=False
        )
        ok = sol.result == optx.RESULTS.successful
        return sol.value, ok if use_flag else jnp.ones_like(ok)

    q, ok = jax.vmap(one)(q0s)
    res = jax.vmap(lambda q: jnp.max(jnp.abs(residual(q, scene))))(q)
    return q, ok, res


_solve_batch = cpu_jit(_solve_batch_body)


def solve_equilibria(
    scene: Scene, q0s, rtol=1e-10, atol=1e-10, max_steps=200, method="newton"
):
    """Equilibrium solves from a batch of starts `q0s` (shape `(B, 3 n)`), all in
    one compiled call; `method` is `'newton'`, `'dogleg'` or `'lm'` (see
    `find_equilibria`).

    Returns (states `(B, 6 n)`, converged mask, max |residual|)."""
    _check_method(method)
    q0s = jnp.asarray(q0s, dtype=jnp.float64)
    q, ok, res = _solve_batch(scene, q0s, rtol, atol, max_steps, method)
    n = _n(scene)
    ys = jax.vmap(lambda q: state_from_q(q, n))(q)
    return np.asarray(ys), np.asarray(ok) & (np.asarray(res) < 1e-6), np.asarray(res)


def solve_equilibrium(scene: Scene, y_guess):
    """One equilibrium from the state `y_guess` (its velocities are ignored).

    Raises `RuntimeError` when Newton does not converge."""
    n = _n(scene)
    q0 = q_from_state(jnp.asarray(y_guess, dtype=jnp.float64), n)
    ys, ok, res = solve_equilibria(scene, q0[None])
    if not ok[0]:
        raise RuntimeError(f"equilibrium solve failed (residual {res[0]:.3g}).")
    return ys[0]


def tandem_start(model: Tandem, l0, psi1, psi2):
    """Start of the S1 grid: turret at the origin, shuttle bow `l0 + 1` m behind the
    FPSO stern along the shuttle heading."""
    e1 = jnp.stack([jnp.cos(psi1), jnp.sin(psi1)])
    e2 = jnp.stack([jnp.cos(psi2), jnp.sin(psi2)])
    p1 = -model.x_t * e1
    P1 = p1 + model.x_h1 * e1
    P2 = P1 - (l0 + 1.0) * e2
    p2 = P2 - model.x_h2 * e2
    z = jnp.zeros(3)
    return jnp.concatenate([p1, psi1[None], z, p2, psi2[None], z])


@cpu_jit(tiered=True)
def _jacobian(scene, y):
    return jax.jacfwd(lambda y: scene.vector_field(0.0, y))(y)


def jacobian(scene: Scene, y):
    """The dense Jacobian dF/dX of the scene's vector field at state `y`."""
    return np.asarray(_jacobian(scene, jnp.asarray(y, dtype=jnp.float64)))


def classify(eigs, tol=1e-9):
    """Stable (all Re < 0), saddle (a real eigenvalue > 0) or oscillatory unstable
    (a complex pair with Re > 0 and no real positive one)."""
    eigs = np.asarray(eigs)
    unstable = eigs[eigs.real > tol]
    if unstable.size == 0:
        return STABLE
    real = np.abs(unstable.imag) <= 1e-9 * np.maximum(1.0, np.abs(unstable.real))
    return SADDLE if np.any(real) else OSCILLATORY


def stability(scene: Scene, y):
    """(eigenvalues sorted by decreasing real part, class) at equilibrium `y`."""
    eigs = np.linalg.eigvals(jacobian(scene, y))
    # jnp.linalg.eigvals gives the same on CPU (host LAPACK); numpy avoids a
    # recompilation per call here.
    eigs = eigs[np.argsort(-eigs.real)]
    return eigs, classify(eigs)


@dataclasses.dataclass
class Equilibrium:
    """One equilibrium: state, hawser tension, clearance, eigenvalues, class."""

    y: np.ndarray
    tension: float
    clearance: float
    eigenvalues: np.ndarray
    kind: str

    @property
    def admissible(self) -> bool:
        return self.clearance > 0

    @property
    def stable(self) -> bool:
        return self.kind == STABLE

    @property
    def headings_deg(self):
        return np.degrees(np.asarray(wrap(jnp.asarray(self.y[2::6]))))


def _dedupe(ys, pos_tol=1.0, ang_tol=0.01):
    """Indices of the distinct states among `ys` (first of each cluster)."""
    kept = []
    for i, y in enumerate(ys):
        eta = y.reshape(-1, 6)[:, :3]
        dup = False
        for k in kept:
            ek = ys[k].reshape(-1, 6)[:, :3]
            dpos = np.max(np.abs(eta[:, :2] - ek[:, :2]))
            dang = np.max(np.abs(np.angle(np.exp(1j * (eta[:, 2] - ek[:, 2])))))
            if dpos < pos_tol and dang < ang_tol:
                dup = True
                break
        if not dup:
            kept.append(i)
    return kept


def grid_starts(scene: Scene, n_grid=14):
    """The S1 grid of starts over (psi1, psi2), shape `(n_grid^2, 6)` (in q)."""
    hawser = _hawser(scene)
    ang = jnp.linspace(-math.pi, math.pi, n_grid, endpoint=False)
    p1, p2 = jnp.meshgrid(ang, ang, indexing="ij")
    ys = jax.vmap(lambda a, b: tandem_start(scene.model, hawser.l0, a, b))(
        p1.ravel(), p2.ravel()
    )
    return jax.vmap(lambda y: q_from_state(y, 2))(ys)


def _hawser(scene):
    hs = [e for e in scene.effects if isinstance(e, Hawser)]
    if not hs:
        raise ValueError("the scene has no `Hawser`: not a tandem equilibrium scene.")
    return hs[0]


def _equilibria_batch(scene, q0s, rtol, atol, max_steps, method="newton", jac="loop"):
    """Solve from all starts and evaluate tension, clearance and Jacobian of each
    solution (the body of `find_equilibria`'s compiled call; `jac` as
    `_newton_batch`'s `jacobian`)."""
    if method == "newton":
        q, ok, res, J = _newton_batch(scene, q0s, rtol, atol, max_steps, jac)
    else:
        q, ok, res = _solve_batch_body(scene, q0s, rtol, atol, max_steps, method)
        J = None
    hawser = _hawser(scene)
    ys = jax.vmap(lambda q: state_from_q(q, 2))(q)

    def props(y):
        eta = y.reshape(2, 6)[:, :3]
        T = hawser.tension(scene.model, eta, jnp.zeros((2, 3)))
        return T, hull_clearance(scene.model, eta)

    T, clr = jax.vmap(props)(ys)
    if J is None:
        J = jax.vmap(lambda y: _jacobian(scene, y))(ys)
    return ys, ok & (res < 1e-6), T, clr, J


def _equilibria_map_body(scenes, n_grid, rtol, atol, max_steps, method):
    """`_equilibria_batch` from the `grid_starts` of each of a batch of scenes,
    vmapped inside one compiled call (a vmap of a compiled function would trace its
    body twice: once, then batched)."""

    def one(scene):
        q0s = grid_starts(scene, n_grid)
        return _equilibria_batch(scene, q0s, rtol, atol, max_steps, method, "after")

    return eqx.filter_vmap(one)(scenes)


_equilibria_map = cpu_jit(_equilibria_map_body)


def _equilibria_one_body(scene, n_grid, rtol, atol, max_steps, method):
    """`_equilibria_batch` from the `grid_starts` of one scene: the program of
    `find_equilibria`, without the scenes' `vmap` (batching the solves for a batch
    of one only lengthens their trace: docs/performance.md)."""
    q0s = grid_starts(scene, n_grid)
    return _equilibria_batch(scene, q0s, rtol, atol, max_steps, method)


_equilibria_one = cpu_jit(_equilibria_one_body)


def _collect(ys, ok, T, clr, J, taut_tension):
    ys, ok, T, clr, J = (np.asarray(a) for a in (ys, ok, T, clr, J))
    keep = ok & (T > taut_tension)
    ys, T, clr, J = ys[keep].copy(), T[keep], clr[keep], J[keep]
    # Headings wrapped to (-pi, pi] for de-duplication and output.
    ys[:, 2::6] = np.angle(np.exp(1j * ys[:, 2::6]))
    out = []
    for i in _dedupe(ys):
        eigs = np.linalg.eigvals(J[i])
        eigs = eigs[np.argsort(-eigs.real)]
        out.append(
            Equilibrium(
                y=ys[i],
                tension=float(T[i]),
                clearance=float(clr[i]),
                eigenvalues=eigs,
                kind=classify(eigs),
            )
        )
    out.sort(key=lambda e: (e.y[2], e.y[8]))
    return out


@single_blas_thread
def find_equilibria(
    scene: Scene,
    n_grid=14,
    taut_tension=1.0,
    rtol=1e-10,
    atol=1e-10,
    max_steps=200,
    method="newton",
):
    """All taut-hawser equilibria of a tandem scene (spec S1).

    Solves from the `n_grid` x `n_grid` starts of `grid_starts`, all at once; keeps
    converged solutions (max |residual| < 1e-6) with T_h > `taut_tension` N,
    de-duplicates them (1 m, 0.01 rad) and classifies each by the eigenvalues of
    its `jacfwd` Jacobian. Returns a list of `Equilibrium`, sorted by FPSO heading.

    `method`: `'newton'` (optimistix Newton's iteration, the default: it finds
    the most roots), `'dogleg'` (Powell dogleg trust region, the optimistix analogue of
    MINPACK hybrd) or `'lm'` (Levenberg-Marquardt; slow to converge here, finds
    the fewest). The counts of the non-admissible (overlapping-hull) roots depend
    on the method; no method reproduces every cell of the spec's table (see
    experiments/results/tanker_equilibria_methods.md).
    """
    _check_tandem(scene)
    return _find_map([scene], n_grid, taut_tension, rtol, atol, max_steps, method)[0]


def _check_tandem(scene):
    if not isinstance(scene.model, Tandem):
        raise ValueError("`find_equilibria` needs a Tandem scene.")
    _hawser(scene)


def find_equilibria_map(scenes, **options):
    """`find_equilibria` for several scenes of one structure (e.g. a wind map),
    all solved in one vmapped, compiled call; `options` as for `find_equilibria`.
    Returns a list of lists."""
    scenes = list(scenes)
    for sc in scenes:
        _check_tandem(sc)
    try:
        args = inspect.signature(find_equilibria).bind(None, **options)
    except TypeError as e:
        raise ValueError(f"`find_equilibria_map`: {e}") from None
    args.apply_defaults()
    return _find_map(scenes, *list(args.arguments.values())[1:])


def _find_map(scenes, n_grid, taut_tension, rtol, atol, max_steps, method):
    _check_method(method)
    options = (n_grid, rtol, atol, max_steps, method)
    # a later process skips tracing the solves (`jaxstring._programs`)
    if len(scenes) == 1:
        out = _programs.call_or_jit(
            _equilibria_one_body, _equilibria_one, scenes[0], *options
        )
        return [_collect(*out, taut_tension)]
    batch = jax.tree_util.tree_map(
        lambda *a: host_op(lambda xp, *a: xp.stack(a), *a), *scenes
    )
    out = _programs.call_or_jit(
        _equilibria_map_body,
        _equilibria_map,
        *(batch, n_grid, rtol, atol, max_steps, method),
    )
    rows = lambda i: (host_op(lambda xp, a: a[i], a) for a in out)
    return [_collect(*rows(i), taut_tension) for i in range(len(scenes))]


def counts(equilibria):
    """(taut, admissible, stable-and-admissible) counts of a list of equilibria."""
    adm = [e for e in equilibria if e.admissible]
    return len(equilibria), len(adm), sum(e.stable for e in adm)


# ---------------------------------------------------------------------------
# Limit cycles


def _crossings(t, x):
    """Up-crossing times of x through 0 (linear interpolation)."""
    i = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


def measure_limit_cycle(traj, t_from):
    """Period and amplitudes of a (fishtailing) run over `t > t_from`.

    Returns a dict: `period` (s, mean spacing of the up-crossings of the shuttle
    heading about its mean), `shuttle_yaw`, `fpso_yaw` (half peak-to-peak, deg),
    `lateral_excursion` (peak-to-peak east position of the shuttle, m), `span_min`,
    `span_max` (m), `tension_max`, `tension_min` (N), `n_cycles`."""
    n = int(traj.n_valid)
    t = np.asarray(traj.ts)[:n]
    m = t > t_from
    t = t[m]
    ys = np.asarray(traj.ys)[:n][m]
    psi1 = np.unwrap(ys[:, 2])
    psi2 = np.unwrap(ys[:, 8])
    span = np.asarray(traj.span)[:n][m]
    T = np.asarray(traj.tension)[:n][m]
    x = psi2 - np.mean(psi2)
    up = _crossings(t, x)
    period = float(np.mean(np.diff(up))) if up.size >= 2 else float("nan")
    return {
        "period": period,
        "n_cycles": max(int(up.size) - 1, 0),
        "shuttle_yaw": float(np.degrees(np.ptp(psi2)) / 2),
        "fpso_yaw": float(np.degrees(np.ptp(psi1)) / 2),
        "lateral_excursion": float(np.ptp(ys[:, 7])),
        "span_min": float(np.min(span)),
        "span_max": float(np.max(span)),
        "tension_min": float(np.min(T)),
        "tension_max": float(np.max(T)),
    }


# ---------------------------------------------------------------------------
# Parameter sweeps of the aligned equilibrium (S0, S3b)


def _crossing_of(xs, values):
    """First x where `values` goes from < 0 to >= 0 or from > 0 to <= 0 (linear)."""
    xs, v = np.asarray(xs), np.asarray(values)
    s = np.sign(v)
    i = np.nonzero(s[:-1] * s[1:] <= 0)[0]
    if i.size == 0:
        return float("nan")
    i = i[0]
    return float(xs[i] - v[i] * (xs[i + 1] - xs[i]) / (v[i + 1] - v[i]))


def leading_eigenvalues(scenes_and_states):
    """Eigenvalue with the largest real part of each (scene, equilibrium)."""
    out = []
    for scene, y in scenes_and_states:
        eigs, _ = stability(scene, y)
        out.append(eigs[0])
    return np.asarray(out)


def hopf_sweep(make_scene, F_values):
    """Leading eigenvalue of the aligned equilibrium over the astern pull.

    `make_scene(F_ast)` returns a scene whose `y0` is (near) the aligned
    equilibrium. Returns (F values, equilibria, leading eigenvalues, Hopf point
    F* (N, linear interpolation of Re = 0), tension at F*)."""
    eqs, lead = [], []
    for F in F_values:
        sc = make_scene(float(F))
        y = solve_equilibrium(sc, sc.y0)
        eigs, _ = stability(sc, y)
        # Leading complex pair (the fishtail mode).
        cplx = eigs[np.abs(eigs.imag) > 1e-9]
        eqs.append(y)
        lead.append(cplx[0] if cplx.size else eigs[0])
    lead = np.asarray(lead)
    F_star = _crossing_of(F_values, lead.real)
    return np.asarray(F_values), np.asarray(eqs), lead, F_star


def pitchfork_sweep(make_scene, x_values):
    """Largest real eigenvalue of the heading-into-current FPSO equilibrium over the
    turret position; returns (x values, leading eigenvalues, crossing x*)."""
    lead = []
    for x in x_values:
        sc = make_scene(float(x))
        y = solve_equilibrium(sc, sc.y0)
        eigs, _ = stability(sc, y)
        lead.append(eigs[0])
    lead = np.asarray(lead)
    return np.asarray(x_values), lead, _crossing_of(x_values, lead.real)


def rotate_state(y, angle):
    """Rotate a whole tandem state about the earth origin by `angle` (rad)."""
    y = np.array(y, dtype=float).reshape(-1, 6)
    R = np.asarray(rot(angle))
    y[:, :2] = y[:, :2] @ R.T
    y[:, 2] += angle
    return y.reshape(-1)


# The columns of a table of `controlled_metrics`, in order.
CONTROLLED_METRICS = (
    "span_error",
    "heading_error",
    "span_min",
    "clearance_min",
    "X_peak",
    "N_peak",
    "psi1_final",
    "X_final",
    "N_final",
    "ok",
)


def controlled_metrics(traj, d_ref, X_max, N_max, t_after=3000.0):
    """S4 acceptance quantities of a controlled run.

    Returns a dict: `span_error` (max |d - d_ref| after `t_after`, m),
    `heading_error` (max |y2| after `t_after`, deg), `span_min` (m),
    `clearance_min` (m), `X_peak` (N), `N_peak` (N m), `psi1_final`,
    `psi2_final` (deg), `X_final` (N), `N_final` (N m), `ok` (all four acceptance
    criteria: < 0.5 m, < 0.5 deg, clearance > 0, |X| <= X_max and |N| <= N_max)."""
    n = int(traj.n_valid)
    t = np.asarray(traj.ts)[:n]
    late = t >= t_after
    span = np.asarray(traj.span)[:n]
    y2 = np.degrees(np.asarray(traj.heading_error)[:n])
    ctl = np.asarray(traj.control)[:n]
    hd = np.degrees(np.asarray(traj.headings)[:n])
    out = {
        "span_error": float(np.max(np.abs(span[late] - d_ref)))
        if late.any()
        else np.nan,
        "heading_error": float(np.max(np.abs(y2[late]))) if late.any() else np.nan,
        "span_min": float(np.min(span)),
        "clearance_min": float(np.min(np.asarray(traj.clearance)[:n])),
        "X_peak": float(np.max(np.abs(ctl[:, 0]))),
        "N_peak": float(np.max(np.abs(ctl[:, 1]))),
        "psi1_final": float(hd[-1, 0]),
        "psi2_final": float(hd[-1, 1]),
        "X_final": float(ctl[-1, 0]),
        "N_final": float(ctl[-1, 1]),
    }
    out["ok"] = bool(
        traj.ok
        and n == len(np.asarray(traj.ts))
        and out["span_error"] < 0.5
        and out["heading_error"] < 0.5
        and out["clearance_min"] > 0
        and out["X_peak"] <= float(X_max)
        and out["N_peak"] <= float(N_max)
    )
    return out
