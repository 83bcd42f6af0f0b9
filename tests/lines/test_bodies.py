"""Bodies and rotations (`jaxstring.lines.bodies`), checked with numbers:

- `rotation_matrix` is MoorDyn's R = Rx Ry Rz (scipy's intrinsic "XYZ"), and
  `euler_angles` its inverse with the middle angle in [-pi/2, pi/2];
- `rotation_from_vector` is scipy's rotation vector, exact at and near zero
  (value and derivative dR/dv_i = skew(e_i));
- quaternions (w, x, y, z) round-trip with matrices at every pivot of Shepperd's
  method, and the Hamilton product composes rotations;
- `Body` holds array leaves (differentiable), broadcasts scalars, and refuses bad
  input (a free body with no mass and no volume, named).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxstring  # noqa: F401  (float64)
from jaxstring.lines.bodies import (
    Body,
    euler_angles,
    matrix_to_quat,
    quat_multiply,
    quat_to_matrix,
    rotation_from_vector,
    rotation_matrix,
    skew,
)


Rotation = pytest.importorskip("scipy.spatial.transform").Rotation

ANGLES = np.array(
    [
        [0.0, 0.0, 0.0],
        [0.1, -0.2, 0.3],
        [1.2, 0.7, -2.5],
        [-3.0, 1.4, 3.1],
        [0.4, -1.5, 0.2],
    ]
)


def test_euler_matches_moordyn_and_scipy():
    for a in ANGLES:
        R = np.asarray(rotation_matrix(a))
        ref = Rotation.from_euler("XYZ", a).as_matrix()
        np.testing.assert_allclose(R, ref, atol=1e-15)
        # MoorDyn's Euler2Quat: AngleAxis(x) * AngleAxis(y) * AngleAxis(z)
        rx = Rotation.from_rotvec([a[0], 0, 0]).as_matrix()
        ry = Rotation.from_rotvec([0, a[1], 0]).as_matrix()
        rz = Rotation.from_rotvec([0, 0, a[2]]).as_matrix()
        np.testing.assert_allclose(R, rx @ ry @ rz, atol=1e-15)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
        np.testing.assert_allclose(np.asarray(euler_angles(R)), a, atol=1e-13)


def test_small_angles_are_rotations_about_global_axes():
    J = jax.jacfwd(lambda a: rotation_matrix(a))(jnp.zeros(3))  # (3, 3, 3)
    for i in range(3):
        np.testing.assert_allclose(J[:, :, i], skew(jnp.eye(3)[i]), atol=1e-15)
    # euler_angles inverts rotation_matrix to first order too
    a = jnp.array([0.3, -0.4, 1.1])
    D = jax.jacfwd(lambda a: euler_angles(rotation_matrix(a)))(a)
    np.testing.assert_allclose(D, np.eye(3), atol=1e-13)


def test_rotation_vector():
    for v in ([0.3, -0.2, 0.9], [1e-5, 2e-5, -1e-5], [2.0, 1.0, -2.5], [0, 0, 0]):
        v = np.asarray(v, float)
        ref = Rotation.from_rotvec(v).as_matrix()
        np.testing.assert_allclose(np.asarray(rotation_from_vector(v)), ref, atol=1e-15)
    # exact derivative at zero: dR/dv_i = skew(e_i), finite (no NaN)
    J = jax.jacfwd(rotation_from_vector)(jnp.zeros(3))
    assert np.all(np.isfinite(J))
    for i in range(3):
        np.testing.assert_allclose(J[:, :, i], skew(jnp.eye(3)[i]), atol=1e-15)
    # and across the series switch: derivative against central differences
    v0 = jnp.array([6e-5, -3e-5, 4e-5])  # |v|^2 ~ 6e-9 < 1e-8: the series branch
    for v in (v0, 1.5 * v0):
        J = jax.jacfwd(rotation_from_vector)(v)
        h = 1e-7
        for i in range(3):
            e = jnp.eye(3)[i] * h
            fd = (rotation_from_vector(v + e) - rotation_from_vector(v - e)) / (2 * h)
            np.testing.assert_allclose(J[:, :, i], fd, atol=1e-8)


def test_skew_is_cross():
    a, b = jnp.array([0.3, -1.0, 2.0]), jnp.array([1.5, 0.2, -0.7])
    np.testing.assert_allclose(skew(a) @ b, jnp.cross(a, b), atol=1e-15)


def test_quaternions():
    rng = np.random.default_rng(0)
    mats = [Rotation.from_euler("XYZ", a).as_matrix() for a in ANGLES]
    # one rotation with each of w, x, y, z the largest component (every pivot)
    mats += [Rotation.from_rotvec(np.pi * 0.95 * ax).as_matrix() for ax in np.eye(3)]
    mats += list(Rotation.random(20, random_state=1).as_matrix())
    for R in mats:
        q = np.asarray(matrix_to_quat(R))
        ref = Rotation.from_matrix(R).as_quat()  # scalar last
        ref = np.roll(ref, 1)
        ref = -ref if ref[0] < 0 else ref
        np.testing.assert_allclose(q, ref, atol=1e-14)
        np.testing.assert_allclose(np.asarray(quat_to_matrix(q)), R, atol=1e-14)
    # a non-unit quaternion is normalised
    q = rng.normal(size=4)
    ref = Rotation.from_quat(np.roll(q, -1)).as_matrix()
    np.testing.assert_allclose(np.asarray(quat_to_matrix(q)), ref, atol=1e-14)
    # Hamilton product composes rotations: R(p q) = R(p) R(q)
    p, q = rng.normal(size=4), rng.normal(size=4)
    np.testing.assert_allclose(
        np.asarray(quat_to_matrix(quat_multiply(p, q))),
        np.asarray(quat_to_matrix(p) @ quat_to_matrix(q)),
        atol=1e-14,
    )


def test_body_fields_are_leaves():
    b = Body("free", position=[0.0, 0.0, -70.0], mass=8e6, volume=8000.0,
             inertia=4e9, CdA=0.5, Ca=[1.0, 1.0, 0.0])  # fmt: skip
    assert b.inertia.shape == (3,) and b.CdA.shape == (6,) and b.Ca.shape == (3,)
    assert b.position.dtype == jnp.float64
    leaves = jax.tree_util.tree_leaves(eqx.filter(b, eqx.is_inexact_array))
    assert len(leaves) == 8  # position rotation mass cg inertia volume CdA Ca
    # differentiable: d/dyaw of a body-frame point's global position
    g = jax.grad(lambda b: (b.matrix @ jnp.array([5.0, 0.0, 0.0]))[1])(b)
    np.testing.assert_allclose(g.rotation, [0.0, 0.0, 5.0], atol=1e-14)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(kind="floating"), r"unknown body kind 'floating'"),
        (dict(position=[0.0, 0.0]), r"`position of b1` must be of shape \(3,\)"),
        (dict(mass=-1.0), r"`mass of b1` must be a finite number >= 0 kg; got -1.0"),
        (dict(volume=float("nan")), r"`volume of b1` must be finite"),
        (dict(rotation=[0.0, float("inf"), 0.0]), r"`rotation of b1` must be finite"),
        (dict(mass=0.0, volume=0.0), r"b1 is free with `mass` = 0 kg and `volume`"),
        (dict(CdA=[1.0] * 5), r"`CdA of b1` must be of shape \(6,\)"),
    ],
)
def test_body_bad_input(kwargs, match):
    args = dict(kind="free", position=[0.0, 0.0, -70.0], mass=1e6, name="b1")
    args.update(kwargs)
    kind = args.pop("kind")
    with pytest.raises(ValueError, match=match):
        Body(kind, **args)


def test_fixed_body_may_be_massless():
    b = Body("coupled", position=[0.0, 0.0, 0.0])
    assert float(b.mass) == 0.0
