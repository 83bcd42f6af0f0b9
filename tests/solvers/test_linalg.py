"""The implicit solvers' linear algebra on string Jacobians: the band and its
detection, block cyclic reduction against dense solves, the velocity-reduced
(second-order) factorisation, the displacement string's own Jacobian, and the
bordered band of a network with a rigid body's rows; each compiled, as the solvers
run them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring as js
from jaxstring import _linalg

from ..helpers import FORMULATIONS_FAST, dense_jacobian, string_vf


# ---------------------------------------------------------------------------
# Banded linear algebra on string Jacobians
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("formulation", FORMULATIONS_FAST)
def test_string_jacobian_is_block_tridiagonal_and_detected(formulation):
    fn, y, scene = string_vf(formulation, 13)
    assert _linalg.detect_width(fn, y, scene) == 1
    # The dense Jacobian's nonzeros lie within one node of the diagonal...
    n, b = y.shape
    J = np.asarray(dense_jacobian(scene, y, 0.0))
    rows, cols = np.nonzero(J)
    assert np.max(np.abs(rows // b - cols // b)) == 1
    # ... and 3 b coloured JVPs reproduce it exactly.
    bt = jax.jit(
        lambda u, s: _linalg.block_tridiagonal_jacobian(
            lambda v: fn(v, s), u, 1
        ).to_dense()
    )(y, scene)
    assert np.max(np.abs(np.asarray(bt) - J)) <= 1e-14 * np.max(np.abs(J))


def test_detect_width_rejects_global_coupling():
    # Every row depends on every node: no band, dense path.
    def fn(u, a):
        return u * jnp.sum(u) * a

    assert _linalg.detect_width(fn, jnp.ones((20, 4)), jnp.array(2.0)) is None


@pytest.mark.parametrize("formulation", FORMULATIONS_FAST)
@pytest.mark.parametrize(
    "k, c", [(13, 1e-3), pytest.param(27, 1e-4, marks=pytest.mark.slow)]
)
def test_banded_newton_solve_equals_dense(formulation, k, c):
    # Newton matrices I - c J of strings are badly scaled (condition 1e9 ... 1e11:
    # metres next to metres per second), so two backward-stable solvers may differ
    # by up to cond * eps in the forward sense. Block cyclic reduction is backward
    # stable (normwise backward error at round-off), and with one step of
    # iterative refinement it equals the (refined) dense LU solve to 5e-12, seven
    # orders below cond * eps. (Measured: at most 1.2e-12, displacement, k = 27,
    # c = 1e-4, cond 1.3e11, with `factor` compiled as one XLA program as in the
    # solvers; 5.6e-13 when it ran op by op.)
    fn, y, scene = string_vf(formulation, k)
    n, b = y.shape
    J = dense_jacobian(scene, y)
    M = np.eye(n * b) - c * J
    rhs = np.random.default_rng(0).standard_normal((n, b))
    dense = np.linalg.solve(M, rhs.reshape(-1))
    # The dense LU solve, refined with residuals in extended precision: accurate to
    # well below 1e-12 (its own forward error is up to cond * eps).
    for _ in range(2):
        res = M.astype(np.longdouble) @ dense.astype(np.longdouble) - rhs.reshape(-1)
        dense = dense - np.linalg.solve(M, res.astype(np.float64))

    @jax.jit
    def banded(u, s, r):
        # the solve and one step of iterative refinement
        Mb = _linalg.block_tridiagonal_jacobian(lambda v: fn(v, s), u, 1)
        Mb = Mb.scale_shift(1.0, -c)
        fac = _linalg.factor(Mb)
        x = fac.solve(r)
        return x, x + fac.solve(r - Mb.matvec(x))

    x, refined = banded(y, scene, jnp.asarray(rhs))
    xf = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ xf - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(xf))
    )
    assert backward < 1e-15, backward
    forward = np.max(np.abs(xf - dense)) / np.max(np.abs(dense))
    assert forward < 1e-8, forward
    err = np.max(np.abs(np.asarray(refined).reshape(-1) - dense)) / np.max(
        np.abs(dense)
    )
    assert err < 5e-12, err


def test_block_inverse_pivots():
    a = np.random.default_rng(1).standard_normal((30, 6, 6))
    a[:, 0, 0] = 0.0  # a zero leading entry needs a row exchange
    err = np.max(np.abs(np.asarray(_linalg.small_inv(a)) - np.linalg.inv(a)))
    assert err < 1e-10, err


@pytest.mark.parametrize("B", (6, 30))
def test_pivoted_solve_is_as_accurate_as_lapack(B):
    # Gauss-Jordan with partial pivoting (the rigid bodies' mass matrix, a
    # bordered Jacobian's Schur complement): on matrices with rows scaled over
    # 10 orders of magnitude and a zero leading entry, the residual of the
    # solution is as small as LAPACK's (backward stable), and the solution within
    # cond(a) eps of it.
    rng = np.random.default_rng(B)
    a = rng.standard_normal((40, B, B)) * np.exp(rng.uniform(-11, 11, (40, B, 1)))
    a[:, 0, 0] = 0.0
    b = rng.standard_normal((40, B, 3))
    x = np.asarray(_linalg.pivoted_solve(jnp.asarray(a), jnp.asarray(b)))
    ref = np.linalg.solve(a, b)

    def backward(x):  # normwise backward error
        r = np.linalg.norm(a @ x - b, axis=(1, 2))
        return r / (np.linalg.norm(a, axis=(1, 2)) * np.linalg.norm(x, axis=(1, 2)))

    assert np.all(backward(x) < 100 * B * np.finfo(float).eps), np.max(backward(x))
    rel = np.linalg.norm(x - ref, axis=(1, 2)) / np.linalg.norm(ref, axis=(1, 2))
    assert np.all(rel < 10 * np.linalg.cond(a) * np.finfo(float).eps), np.max(rel)
    inv = np.asarray(_linalg.pivoted_inverse(jnp.asarray(a)))
    np.testing.assert_allclose(inv @ b, x, rtol=0, atol=1e-6 * np.max(np.abs(x)))


@pytest.mark.parametrize("B", (1, 2, 3, 4, 6, 12))
def test_block_thomas_and_cyclic_reduction_equal_the_dense_solve(B):
    # Both eliminations of a block-tridiagonal system (the block Thomas algorithm
    # for blocks of at most two rows, cyclic reduction above) solve it to rounding;
    # 13 blocks, so that the reduction has an unpaired last block at some level.
    rng = np.random.default_rng(B)
    N = 13
    L, D, U = (rng.standard_normal((N, B, B)) for _ in range(3))
    D += 4 * B * np.eye(B)
    L[0] = U[-1] = 0.0
    mat = _linalg.BlockTridiagonal(*map(jnp.asarray, (L, D, U)), N, B, 1)
    dense = np.zeros((N * B, N * B))
    for i in range(N):
        dense[i * B : (i + 1) * B, i * B : (i + 1) * B] = D[i]
        if i:
            dense[i * B : (i + 1) * B, (i - 1) * B : i * B] = L[i]
        if i < N - 1:
            dense[i * B : (i + 1) * B, (i + 1) * B : (i + 2) * B] = U[i]
    f = rng.standard_normal((N, B))
    x_ref = np.linalg.solve(dense, f.reshape(-1)).reshape(N, B)
    fac = jax.jit(_linalg.block_factor)(mat)
    assert isinstance(fac, _linalg.ThomasFactor) == (B <= 2)
    for fac in (fac, jax.jit(_linalg.thomas_factor)(mat)):
        x = np.asarray(_linalg.block_solve(fac, jnp.asarray(f)))
        assert np.max(np.abs(x - x_ref)) < 1e-13 * np.max(np.abs(x_ref))
    x = np.asarray(_linalg.bcr_solve(jax.jit(_linalg.bcr_factor)(mat), jnp.asarray(f)))
    assert np.max(np.abs(x - x_ref)) < 1e-13 * np.max(np.abs(x_ref))
    # A model that declares the sequential elimination (mooring lines) gets it for
    # blocks of any size, through a Newton matrix's shift and scale too.
    declared = _linalg.BlockTridiagonal(
        *map(jnp.asarray, (L, D, U)), N, B, 1, sequential=True
    ).scale_shift(0.0, 1.0)
    fac = jax.jit(_linalg.block_factor)(declared)
    assert isinstance(fac, _linalg.ThomasFactor)
    x = np.asarray(_linalg.block_solve(fac, jnp.asarray(f)))
    assert np.max(np.abs(x - x_ref)) < 1e-13 * np.max(np.abs(x_ref))


# ---------------------------------------------------------------------------
# The reduced Newton system of a second-order model (q, v rows, dq/dt = v)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("dim", (2, pytest.param(3, marks=pytest.mark.slow)))
@pytest.mark.parametrize(
    "a, b",
    [
        (1.0, -1e-3),
        pytest.param(1.0, -0.1, marks=pytest.mark.slow),
        pytest.param(100.0, -1.0, marks=pytest.mark.slow),
    ],
)
def test_second_order_factor_equals_dense_solve(dim, a, b):
    # a I + b J as BDF (a = 1, b = -c) and Rodas5P (a = 1 / (h gamma), b = -1) form
    # it: the velocity-reduced solve must be backward stable and equal the
    # (refined) dense one to within the conditioning of I - c A_v - c^2 A_x
    # (c^2 EA k^2 / (mu l^2) ~ 1e6 at c = 0.1: forward errors ~ 1e-10).
    scene = js.string_pendulum(
        k=11, dim=dim, EA=1e6, effects=("gravity", "kelvin_voigt", "slack")
    )
    rng = np.random.default_rng(dim)
    y = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    fn = lambda u: scene.vector_field(0.0, u)
    assert scene.structure.second_order == dim
    fac = lambda u: _linalg.factor(
        _linalg.jacobian(fn, u, 1, second_order=dim).scale_shift(a, b)
    )
    shape = jax.eval_shape(fac, y)
    assert isinstance(shape, _linalg.SecondOrderFactor)
    sfac = shape.sfac
    inverse = sfac.dinv if isinstance(sfac, _linalg.ThomasFactor) else sfac.dinv_last
    assert inverse.shape[-2:] == (dim, dim)  # d x d blocks, not 2d x 2d
    n = y.size
    J = dense_jacobian(scene, y)
    rhs = rng.standard_normal(y.shape)
    M = a * np.eye(n) + b * J
    dense = np.linalg.solve(M, rhs.reshape(-1))
    for _ in range(2):  # refined as in the banded test above
        res = M.astype(np.longdouble) @ dense.astype(np.longdouble) - rhs.reshape(-1)
        dense = dense - np.linalg.solve(M, res.astype(np.float64))
    x = jax.jit(lambda u, r: fac(u).solve(r))(y, jnp.asarray(rhs))
    x = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ x - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(x))
    )
    assert backward < 1e-15, backward
    assert np.max(np.abs(x - dense)) / np.max(np.abs(dense)) < 1e-9


def test_declared_sequential_elimination_reaches_the_reduced_blocks():
    # A mooring line declares the sequential elimination: its velocity-reduced 3 x 3
    # blocks are eliminated by block Thomas; a 3D string's by cyclic reduction.
    deck = js.lines.read_moordyn(js.lines.case_path("WD0050_Chain.txt"))
    string = js.string_pendulum(k=6, dim=3)
    kinds = []
    for scene in (deck, string):
        fn = lambda u, scene=scene: scene.vector_field(0.0, u)
        args = (0.0, None, scene)
        so = _linalg.declared_second_order(fn, scene.y0, args)
        seq = _linalg.declared_sequential(fn, scene.y0, args)
        fac = jax.eval_shape(
            lambda u: _linalg.factor(
                _linalg.jacobian(fn, u, 1, None, so, seq).scale_shift(1.0, -0.01)
            ),
            scene.y0,
        )
        assert so == 3
        kinds.append((seq, type(fac.sfac).__name__))
    assert kinds == [(True, "ThomasFactor"), (False, "BCRFactor")]


def test_declared_second_order_matches_the_jacobian():
    # DisplacementString declares rows (r, r') with dr/dt = r' exactly: the q rows
    # of its Jacobian are [0, I] and touch no other node, with every effect on.
    scene = js.string_pendulum(k=7, dim=2, effects=("gravity", "kelvin_voigt", "slack"))
    y = scene.y0 + 0.01
    n, b = y.shape
    J = dense_jacobian(scene, y, 0.3).reshape(n, b, n, b)
    expect = np.zeros((n, 2, n, b))
    for i in range(n):
        expect[i, :, i, 2:] = np.eye(2)
    assert np.array_equal(J[:, :2], expect)
    # The natural variables declare nothing.
    nat = js.string_pendulum("angle", k=7)
    assert nat.structure.second_order == 0


def test_second_order_factor_refuses_a_wrong_structure():
    # A relation whose q rows couple nodes (not a I + b J of dq/dt = v) gives a NaN
    # factor, so the Newton iteration fails instead of converging to a wrong root.
    scene = js.string_pendulum(k=9)
    fn = lambda u: scene.vector_field(0.0, u) + 0.1 * jnp.roll(u, 1, axis=0)
    y = scene.y0 + 0.01

    @jax.jit
    def solve(u):
        mat = _linalg.jacobian(fn, u, 1, second_order=2).scale_shift(1, -0.1)
        return _linalg.factor(mat).solve(jnp.ones_like(u))

    assert np.all(np.isnan(np.asarray(solve(y))))


@pytest.mark.parametrize("B", (2, 3, 4))
def test_closed_form_inverses_are_as_accurate_as_lapack(B):
    # Adjugate / determinant, no pivoting: on random blocks with rows and columns
    # scaled over 14 orders of magnitude the error stays within cond(a) * eps of
    # LAPACK's pivoted inverse.
    rng = np.random.default_rng(B)
    a = rng.standard_normal((500, B, B))
    a *= np.exp(rng.uniform(-8, 8, (500, B, 1))) * np.exp(
        rng.uniform(-8, 8, (500, 1, B))
    )
    ref = np.linalg.inv(a)
    err = np.max(np.abs(np.asarray(_linalg.small_inv(a)) - ref), axis=(1, 2))
    rel = err / np.max(np.abs(ref), axis=(1, 2))
    assert np.all(rel < np.linalg.cond(a) * np.finfo(float).eps), np.max(rel)


def test_ynnpack_fusions_are_off_in_jaxstrings_compilations():
    # simulate, fit and sweep compile with XLA:CPU's YNNPACK fusions off (they made
    # the coloured Jacobian 4-5x slower at k >= 320, experiments/results/
    # ynn_fusion.md), per compilation: a batched reduction compiled by `cpu_jit`
    # has no YNNPACK fusion, while plain `jax.jit` (the user's code) keeps XLA's
    # default.
    from jaxstring._jit import cpu_jit

    f = lambda x: jnp.sum(x * x[:, ::-1], axis=-1)
    x = jnp.ones((12, 640, 2))
    g = cpu_jit(f)
    assert np.array_equal(np.asarray(g(x)), np.asarray(f(x)))
    ours = g.lower_cpu(x).compile().as_text()
    assert "ynn_fusion" not in ours  # (the test's name is in the metadata)
    users = jax.jit(f).lower(x).compile().as_text()
    if "ynn_fusion" not in users:
        pytest.skip("this jaxlib makes no YNNPACK fusion here anyway")


def test_compile_options_this_xla_does_not_know_are_left_out(monkeypatch):
    # jaxstring's per-compilation options are checked against the running XLA
    # once per process: one it does not know is left out (a solve still compiles
    # and runs), the ones it knows are kept as they are.
    from jaxstring import _jit

    known = _jit.cpu_compiler_options()
    assert known == _jit.CPU_COMPILER_OPTIONS  # every option known to this jaxlib
    unknown = {"xla_cpu_no_such_option_here": True}
    monkeypatch.setattr(_jit, "CPU_COMPILER_OPTIONS", known | unknown)
    _jit._known_options.cache_clear()
    try:
        assert _jit.cpu_compiler_options() == known
        f = _jit.cpu_jit(lambda x: jnp.sum(x * x))
        assert float(f(jnp.arange(4.0))) == 14.0
    finally:
        monkeypatch.undo()
        _jit._known_options.cache_clear()


# ---------------------------------------------------------------------------
# The displacement string's own element-wise Jacobian (`vf_jacobian`)
# ---------------------------------------------------------------------------


# dim = 3 (slow) repeats the element derivatives with a third coordinate; the
# default run's 3-D check is the declared band against the probed one.
@pytest.mark.parametrize("dim", (2, pytest.param(3, marks=pytest.mark.slow)))
@pytest.mark.parametrize(
    "effects",
    [("gravity", "kelvin_voigt"), ("gravity", "kelvin_voigt", "slack"), ()],
)
def test_model_jacobian_equals_autodiff(dim, effects):
    # Random states with stretched, compressed (slack: no force) and moving
    # elements: the written-out element derivatives equal jacfwd of the vector
    # field to rounding.
    scene = js.string_pendulum(k=9, dim=dim, EA=1e6, effects=effects)
    rng = np.random.default_rng(dim + len(effects))
    y = scene.y0 + 0.05 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    eps, _ = scene.model.strain(y)
    assert np.any(eps < 0) and np.any(eps > 0)
    jac = scene.model.vf_jacobian(0.0, y, scene.effects, scene.env)
    assert isinstance(jac, _linalg.SecondOrderJacobian)
    assert jac.p.diag.shape == (9, dim, dim)
    J = dense_jacobian(scene, y)
    err = np.max(np.abs(np.asarray(jac.to_dense()) - J)) / np.max(np.abs(J))
    assert err < 1e-13, err
    # The matrix-vector product and the shift agree with the dense matrix.
    x = rng.standard_normal(y.shape)
    M = jac.scale_shift(2.0, -0.3)
    mv = np.asarray(M.matvec(jnp.asarray(x))).reshape(-1)
    dense = (2.0 * np.eye(J.shape[0]) - 0.3 * J) @ x.reshape(-1)
    assert np.max(np.abs(mv - dense)) / np.max(np.abs(dense)) < 1e-13


@pytest.mark.parametrize("a, b", [(1.0, -1e-3), (100.0, -1.0)])
def test_model_jacobian_factor_equals_dense_solve(a, b):
    # BDF's I - c J and Rodas5P's I / (h gamma) - J, factorised straight from the
    # model's v rows: backward stable, and equal to the dense solve.
    scene = js.string_pendulum(k=11, EA=1e6)
    rng = np.random.default_rng(5)
    y = scene.y0 + 0.01 * jnp.asarray(rng.standard_normal(scene.y0.shape))
    fac = lambda u: _linalg.factor(
        scene.model.vf_jacobian(0.0, u, scene.effects, scene.env).scale_shift(a, b)
    )
    M = a * np.eye(y.size) + b * dense_jacobian(scene, y)
    rhs = rng.standard_normal(y.shape)
    x = jax.jit(lambda u, r: fac(u).solve(r))(y, jnp.asarray(rhs))
    x = np.asarray(x).reshape(-1)
    backward = np.max(np.abs(M @ x - rhs.reshape(-1))) / (
        np.max(np.sum(np.abs(M), axis=1)) * np.max(np.abs(x))
    )
    assert backward < 1e-15, backward
    dense = np.linalg.solve(M, rhs.reshape(-1))
    assert np.max(np.abs(x - dense)) / np.max(np.abs(dense)) < 1e-8


@pytest.mark.parametrize(
    "second_order, hooks, coupled",
    [
        (0, (0, 5), ()),
        (3, (0, 5), ()),
        # the border's rows from the band's JVPs: 3 colours keep nodes 0 and 5
        # apart, nodes 0, 3 and 6 need 4
        (3, (0, 5), (0, 5)),
        (0, (0, 3, 6), (0, 3, 6)),
    ],
)
def test_bordered_jacobian_and_solve_equal_dense(second_order, hooks, coupled):
    # A vessel row (the border) coupled to two chains of springs at scattered rows,
    # the chains' rows (q, v) banded with width 1: the bordered Jacobian equals
    # jacfwd and its Schur-complement solve equals the dense solve.
    rng = np.random.default_rng(7)
    n, k = 9, 1
    K = jnp.asarray(rng.uniform(1.0, 3.0, n - k))
    hook = np.zeros(n - k)
    hook[list(hooks)] = 1.0  # the border pulls these nodes
    hook = jnp.asarray(hook)

    def fn(y):
        vb, q, v = y[:k], y[k:, :3], y[k:, 3:]
        qp = jnp.concatenate([q[:1], q[:-1]])
        qn = jnp.concatenate([q[1:], q[-1:]])
        a = K[:, None] * (qp - 2 * q + qn) + hook[:, None] * (vb[0, :3] - q) ** 3
        dv = a - 0.1 * v
        db = jnp.concatenate([vb[0, 3:], -jnp.sum(hook[:, None] * (vb[0, :3] - q), 0)])
        return jnp.concatenate([db[None], jnp.concatenate([v, dv], axis=1)])

    y = jnp.asarray(rng.standard_normal((n, 6)))
    spec = _linalg.BorderedWidth(width=1, border=k, coupled=coupled)
    # compiled, as the solvers run them (op by op, each operation compiles apart)
    mat = jax.jit(lambda u: _linalg.jacobian(fn, u, spec, second_order=second_order))(y)
    assert isinstance(mat, _linalg.BorderedJacobian)
    J = np.asarray(
        jax.jit(jax.jacfwd(lambda u: fn(u.reshape(y.shape)).reshape(-1)))(y.reshape(-1))
    )
    as_dense = jax.jit(lambda m: m.to_dense())(mat)
    np.testing.assert_allclose(np.asarray(as_dense), J, atol=1e-13)
    solve = jax.jit(lambda m, a, b, r: _linalg.factor(m.scale_shift(a, b)).solve(r))
    for a, b in ((1.0, -0.05), (20.0, -1.0)):
        rhs = rng.standard_normal(y.shape)
        x = np.asarray(solve(mat, a, b, jnp.asarray(rhs))).reshape(-1)
        dense = np.linalg.solve(a * np.eye(y.size) + b * J, rhs.reshape(-1))
        np.testing.assert_allclose(x, dense, rtol=1e-11, atol=1e-12)


@pytest.mark.parametrize("coupled", [(), (0, 5)])
def test_bordered_jacobian_of_an_implicit_relation_keeps_its_identity(coupled):
    # A border of two rows whose second row the vector field neither reads nor
    # changes (a rigid object's unused components): the model names the entries in
    # use (`columns`). In the vector field's Jacobian the others' columns are zero;
    # in an implicit stage's relation u - c f(y + c u) and a tangent solve's
    # c J v - v they are the identity's: the bordered Jacobian of each relation
    # equals jacfwd, and so does its solve.
    rng = np.random.default_rng(11)
    n, k = 10, 2
    K = jnp.asarray(rng.uniform(1.0, 3.0, n - k))
    hook = np.zeros(n - k)
    hook[[0, 5]] = 1.0
    hook = jnp.asarray(hook)

    def fn(y):
        vb, q, v = y[0], y[k:, :3], y[k:, 3:]
        qp = jnp.concatenate([q[:1], q[:-1]])
        qn = jnp.concatenate([q[1:], q[-1:]])
        a = K[:, None] * (qp - 2 * q + qn) + hook[:, None] * (vb[:3] - q) ** 3
        db = jnp.concatenate([vb[3:], -jnp.sum(hook[:, None] * (vb[:3] - q), 0)])
        border = jnp.stack([db, jnp.zeros(6)])
        return jnp.concatenate([border, jnp.concatenate([v, a - 0.1 * v], axis=1)])

    y = jnp.asarray(rng.standard_normal((n, 6)))
    spec = _linalg.BorderedWidth(1, k, coupled, tuple(range(6)))
    c = 0.05
    relations = {
        "stage": lambda u: u - c * fn(y + c * u),
        "tangent": lambda u: c * jax.jvp(fn, (y,), (u,))[1] - u,
        "vector field": fn,
    }
    for name, g in relations.items():
        mat = jax.jit(lambda u: _linalg.jacobian(g, u, spec, second_order=3))(y)
        J = np.asarray(
            jax.jacfwd(lambda u: g(u.reshape(y.shape)).reshape(-1))(y.reshape(-1))
        )
        dense = np.asarray(jax.jit(lambda m: m.to_dense())(mat))
        np.testing.assert_allclose(dense, J, atol=1e-13, err_msg=name)
        if name != "vector field":
            rhs = rng.standard_normal(y.shape)
            x = np.asarray(
                jax.jit(lambda m, r: _linalg.factor(m).solve(r))(mat, jnp.asarray(rhs))
            )
            np.testing.assert_allclose(
                x.reshape(-1),
                np.linalg.solve(J, rhs.reshape(-1)),
                rtol=1e-10,
                atol=1e-12,
                err_msg=name,
            )


@pytest.mark.parametrize(
    "deck, EI, width",
    [
        ("RodHanging.txt", None, 1),
        pytest.param("BodiesAndRods.dat", None, 1, marks=pytest.mark.slow),
        # bending: the ropes clamped to the rod's ends, nodes two apart coupled
        pytest.param("RodHanging.txt", 1e5, 2, marks=pytest.mark.slow),
    ],
)
def test_network_with_rigid_rows_orders_them_as_the_border(deck, EI, width):
    # A rod hung by two ropes, a body with three lines (and a pinned rod): the
    # rigid objects' rows come first as the Jacobian's border, the lines' nodes
    # form a band behind it (width 1, 2 with bending), and the Jacobian built
    # from that structure (the border's rows from the band's coloured JVPs,
    # through the rows the model names as coupled) is the vector field's: J v
    # equals its JVP for random v, and its Newton solve x of (I - h J) x = r
    # gives back r.
    import equinox as eqx

    from jaxstring import lines

    scene = lines.read_moordyn(lines.case_path(deck), static=False)
    if EI is not None:
        EIs = jnp.full(scene.model.n_lines, EI)
        scene = eqx.tree_at(
            lambda s: s.model.EI, scene, EIs, is_leaf=lambda x: x is None
        )
    st = scene.structure
    assert st.border > 0 and st.bandwidth == width and st.second_order == 3
    y = scene.y0 + 0.01 * jax.random.normal(jax.random.PRNGKey(0), scene.y0.shape)
    vs = jax.random.normal(jax.random.PRNGKey(1), (3,) + y.shape)
    spec = _linalg.choose_structure(lambda u, s: s.vector_field(0.3, u), y, scene)
    assert spec.coupled
    k, h = st.border, 1e-3

    def check(u, s, vs):
        fn = lambda v: s.vector_field(0.3, v)
        mat = _linalg.jacobian(fn, u, spec, None, 3, True)
        assert isinstance(mat, _linalg.BorderedJacobian)

        def matvec(v):
            vb, vl = v[:k].reshape(-1), v[k:]
            top = mat.A @ vb + mat.R @ vl.reshape(-1)
            low = (mat.C @ vb).reshape(vl.shape) + mat.band.matvec(vl)
            return jnp.concatenate([top.reshape(k, -1), low])

        jvps = jax.vmap(lambda v: jax.jvp(fn, (u,), (v,))[1])(vs)
        fac = _linalg.factor(mat.scale_shift(1.0, -h))
        back = jax.vmap(lambda r: (lambda x: x - h * matvec(x))(fac.solve(r)))(vs)
        return jax.vmap(matvec)(vs), jvps, back

    from jaxstring._jit import cpu_jit

    # compiled as the solvers compile it (XLA:CPU's options for solves)
    Jv, jvps, back = cpu_jit(check)(y, scene, vs)
    scale = np.max(np.abs(np.asarray(jvps)))
    assert np.max(np.abs(np.asarray(Jv - jvps))) <= 1e-12 * scale
    np.testing.assert_allclose(np.asarray(back), np.asarray(vs), rtol=0, atol=1e-10)
    # no LAPACK call (the rigid bodies' solve, the Schur complement's): a step loop
    # holding one is never one whole-loop kernel on XLA:CPU. (With bending the band's
    # 12 x 12 blocks are inverted by LAPACK, `small_inv`.)
    if EI is None:
        assert "custom_call" not in cpu_jit(check).lower_cpu(y, scene, vs).as_text()
