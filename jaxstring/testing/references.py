"""External reference integrators on the identical right-hand side of a jaxstring scene.

Every peer integrates the same flattened ODE y' = f(t, y), where
``f = jax.jit(scene.vector_field)`` on the flattened state, and (unless it uses its
own finite differences) the same Jacobian ``jax.jit(jax.jacfwd(f))``:

* scipy ``solve_ivp``: Radau, BDF, LSODA;
* SUNDIALS through scikit-sundae: CVODE (BDF) and IDA (residual F = y' - f(t, y),
  Jacobian dF/dy + cj dF/dy' = cj I - J).

Jacobian variants (``jac=``):

* ``"jax"``: the dense JAX Jacobian;
* ``"jax-band"``: the same Jacobian handed over in the peer's banded/sparse form
  (CVODE/IDA band solver, LSODA packed band, Radau/BDF sparse CSC + SuperLU);
* ``"fd"``: the peer's own dense finite-difference Jacobian (as a user would start);
* ``"fd-band"``: the peer's finite differences with the band/sparsity pattern.

The JIT compile of f and its Jacobian is timed separately (``JaxRHS.compile``).
Peers that are not installed are skipped (``available()``); they live in the
optional ``bench`` extra (``pip install ".[bench]"``), never in jaxstring's core.
Used by the tests and the benchmarks; ``experiments/references.py`` compares them
on one scene.
"""

import importlib.util
import time

import jax
import jax.numpy as jnp
import numpy as np


PEERS = ("scipy-Radau", "scipy-BDF", "scipy-LSODA", "cvode-BDF", "ida")
JACOBIANS = ("jax", "jax-band", "fd", "fd-band")


def available() -> dict:
    """Which peers can run here: name -> bool."""
    has_scipy = importlib.util.find_spec("scipy") is not None
    has_sundae = importlib.util.find_spec("sksundae") is not None
    return {
        "scipy-Radau": has_scipy,
        "scipy-BDF": has_scipy,
        "scipy-LSODA": has_scipy,
        "cvode-BDF": has_sundae,
        "ida": has_sundae,
    }


class BudgetExceeded(RuntimeError):
    """The peer used more right-hand-side evaluations than allowed."""


class JaxRHS:
    """The scene's vector field on flat float64 NumPy vectors, JIT-compiled by JAX.

    Counts calls (`nfev`, `njev`) and stops a run past `max_fev` evaluations.
    """

    def __init__(self, scene, max_fev: int = 2_000_000):
        self.scene = scene
        self.shape = tuple(scene.y0.shape)
        self.n = int(np.prod(self.shape))
        self.t0 = float(scene.t0)
        self.t1 = float(scene.t1)
        self.y0 = np.asarray(scene.y0, dtype=np.float64).reshape(-1)
        self.max_fev = max_fev
        shape = self.shape

        # The scene is closed over: a reference is never differentiated, and constants
        # keep the per-call overhead minimal.
        def flat_f(t, y):
            return scene.vector_field(t, y.reshape(shape)).reshape(-1)

        def end_mass(ys):
            def one(y):
                obs = scene.observables(y.reshape(shape))
                return obs["positions"][-1]

            return jax.vmap(one)(ys)

        self._flat_f = flat_f
        self._f = jax.jit(flat_f)
        self._jac = jax.jit(jax.jacfwd(flat_f, argnums=1))
        self._end_mass = jax.jit(end_mass)
        self.compile_s = None
        self.lband = self.uband = None
        self.sparsity = None
        self.reset()

    def reset(self):
        self.nfev = 0
        self.njev = 0

    def compile(self) -> float:
        """JIT-compile f and its Jacobian; find the band; return the seconds taken."""
        if self.compile_s is not None:
            return self.compile_s
        t0 = time.perf_counter()
        jax.block_until_ready(self._f(self.t0, self.y0))
        jax.block_until_ready(self._jac(self.t0, self.y0))
        self.compile_s = time.perf_counter() - t0
        # Band of the Jacobian: union of the patterns at a few perturbed states.
        rng = np.random.default_rng(0)
        pattern = np.zeros((self.n, self.n), bool)
        for _ in range(3):
            y = self.y0 + 1e-3 * rng.standard_normal(self.n)
            pattern |= np.asarray(self._jac(self.t0, y)) != 0
        i, j = np.nonzero(pattern)
        self.lband = int(max(np.max(i - j), 0))
        self.uband = int(max(np.max(j - i), 0))
        ii, jj = np.indices((self.n, self.n))
        self.sparsity = ((ii - jj) <= self.lband) & ((jj - ii) <= self.uband)
        # Banded Jacobian by column colouring: columns j and j + w never share a
        # row inside the band (w = lband + uband + 1), so w JVPs give every entry.
        w = self.lband + self.uband + 1
        seeds = np.zeros((self.n, w))
        seeds[np.arange(self.n), np.arange(self.n) % w] = 1.0
        seeds = jnp.asarray(seeds)
        f = self._flat_f

        def compressed(t, y):
            push = lambda s: jax.jvp(lambda z: f(t, z), (y,), (s,))[1]
            return jax.vmap(push, in_axes=1, out_axes=1)(seeds)

        self._jac_compressed = jax.jit(compressed)
        self.band_i, self.band_j = np.nonzero(self.sparsity)
        self._band_col = self.band_j % w
        t0 = time.perf_counter()
        jax.block_until_ready(self._jac_compressed(self.t0, self.y0))
        self.compile_s += time.perf_counter() - t0
        return self.compile_s

    def f(self, t, y):
        self.nfev += 1
        if self.nfev > self.max_fev:
            raise BudgetExceeded(f"more than {self.max_fev} right-hand-side calls")
        return np.asarray(self._f(t, y))

    def jac(self, t, y):
        self.njev += 1
        return np.asarray(self._jac(t, y))

    def jac_band_values(self, t, y):
        """Jacobian entries inside the band, at (band_i, band_j), from w JVPs."""
        self.njev += 1
        C = np.asarray(self._jac_compressed(t, y))
        return C[self.band_i, self._band_col]

    def jac_sparse(self, t, y):
        from scipy.sparse import csc_matrix

        vals = self.jac_band_values(t, y)
        return csc_matrix((vals, (self.band_i, self.band_j)), shape=(self.n, self.n))

    def jac_packed(self, t, y):
        """LSODA's packed band: packed[uband + i - j, j] = J[i, j]."""
        vals = self.jac_band_values(t, y)
        packed = np.zeros((self.lband + self.uband + 1, self.n))
        packed[self.uband + self.band_i - self.band_j, self.band_j] = vals
        return packed

    def end_mass(self, ys) -> np.ndarray:
        """End-mass positions `(T, dim)` of flat states `ys` `(T, n)`, m."""
        return np.asarray(self._end_mass(jnp.asarray(ys)))

    def call_cost_us(self, repeats: int = 200) -> tuple:
        """Median wall time of one f call and one Jacobian call from NumPy, us."""
        self.compile()
        out = []
        for fn in (self._f, self._jac):
            ts = []
            for _ in range(repeats if fn is self._f else max(repeats // 10, 5)):
                t0 = time.perf_counter()
                np.asarray(fn(self.t0, self.y0))
                ts.append(time.perf_counter() - t0)
            out.append(1e6 * float(np.median(ts)))
        return tuple(out)


def _scipy(rhs, method, ts, rtol, atol, jac):
    from scipy.integrate import solve_ivp

    kw = {}
    if jac == "jax":
        kw["jac"] = rhs.jac
    elif jac == "jax-band":
        if method == "LSODA":
            kw.update(jac=rhs.jac_packed, lband=rhs.lband, uband=rhs.uband)
        else:
            kw["jac"] = rhs.jac_sparse
    elif jac == "fd-band":
        if method == "LSODA":
            kw.update(lband=rhs.lband, uband=rhs.uband)
        else:
            kw["jac_sparsity"] = rhs.sparsity
    sol = solve_ivp(
        rhs.f,
        (rhs.t0, rhs.t1),
        rhs.y0,
        method=method,
        t_eval=ts,
        rtol=rtol,
        atol=atol,
        **kw,
    )
    ok = bool(sol.success) and sol.y.shape[1] == len(ts)
    return {
        "ys": sol.y.T if ok else None,
        "ok": ok,
        "message": str(sol.message),
        "nlu": int(getattr(sol, "nlu", 0)),
    }


def _sundae_band(rhs, jac, kw):
    if jac in ("jax-band", "fd-band"):
        kw.update(linsolver="band", lband=rhs.lband, uband=rhs.uband)


def _cvode(rhs, ts, rtol, atol, jac):
    from sksundae.cvode import CVODE

    def rhsfn(t, y, yp):
        yp[:] = rhs.f(t, y)

    kw = {}
    if jac == "jax":

        def jacfn(t, y, yp, JJ):
            JJ[:, :] = rhs.jac(t, y)

        kw["jacfn"] = jacfn
    elif jac == "jax-band":
        bi, bj = rhs.band_i, rhs.band_j

        def jacfn(t, y, yp, JJ):
            JJ[bi, bj] = rhs.jac_band_values(t, y)

        kw["jacfn"] = jacfn
    _sundae_band(rhs, jac, kw)
    solver = CVODE(
        rhsfn, method="BDF", rtol=rtol, atol=atol, max_num_steps=1_000_000, **kw
    )
    sol = solver.solve(np.asarray(ts), rhs.y0)
    ok = bool(sol.success) and sol.y.shape[0] == len(ts)
    return {"ys": sol.y if ok else None, "ok": ok, "message": str(sol.message)}


def _ida(rhs, ts, rtol, atol, jac):
    from sksundae.ida import IDA

    def resfn(t, y, yp, res):
        res[:] = yp - rhs.f(t, y)

    kw = {}
    if jac == "jax":
        eye = np.eye(rhs.n)

        def jacfn(t, y, yp, res, cj, JJ):
            JJ[:, :] = cj * eye - rhs.jac(t, y)

        kw["jacfn"] = jacfn
    elif jac == "jax-band":
        bi, bj = rhs.band_i, rhs.band_j
        diag = (bi == bj).astype(np.float64)

        def jacfn(t, y, yp, res, cj, JJ):
            JJ[bi, bj] = cj * diag - rhs.jac_band_values(t, y)

        kw["jacfn"] = jacfn
    _sundae_band(rhs, jac, kw)
    solver = IDA(resfn, rtol=rtol, atol=atol, max_num_steps=1_000_000, **kw)
    yp0 = np.asarray(rhs._f(rhs.t0, rhs.y0))
    sol = solver.solve(np.asarray(ts), rhs.y0, yp0)
    ok = bool(sol.success) and sol.y.shape[0] == len(ts)
    return {"ys": sol.y if ok else None, "ok": ok, "message": str(sol.message)}


def solve(rhs: JaxRHS, peer: str, ts, rtol: float, atol: float, jac: str = "jax"):
    """Integrate with one peer; return a dict: ys (T, n) or None, ok, message,
    nfev, njev (calls of the JAX f and Jacobian), wall_s."""
    if peer not in PEERS:
        raise ValueError(f"`peer` must be one of {PEERS}; got {peer!r}.")
    if jac not in JACOBIANS:
        raise ValueError(f"`jac` must be one of {JACOBIANS}; got {jac!r}.")
    rhs.compile()
    rhs.reset()
    ts = np.asarray(ts, dtype=np.float64)
    t0 = time.perf_counter()
    try:
        if peer.startswith("scipy-"):
            out = _scipy(rhs, peer.split("-", 1)[1], ts, rtol, atol, jac)
        elif peer == "cvode-BDF":
            out = _cvode(rhs, ts, rtol, atol, jac)
        else:
            out = _ida(rhs, ts, rtol, atol, jac)
    except BudgetExceeded as e:
        out = {"ys": None, "ok": False, "message": str(e)}
    except Exception as e:  # a peer's own failure is a result, not a crash
        out = {"ys": None, "ok": False, "message": f"{type(e).__name__}: {e}"}
    out["wall_s"] = time.perf_counter() - t0
    out["nfev"] = rhs.nfev
    out["njev"] = rhs.njev
    return out
