"""Bending stiffness of mooring lines: MoorDyn v2's nodal bending forces.

A line with bending stiffness EI (N m^2) carries at each interior node i the
bending moment M_i = EI K_i, with the curvature of the two segments that meet there

    K_i = 4 sin(theta_i / 2) / (l_{i-1} + l_i),

theta_i the angle between the segment directions q_{i-1} and q_i and l the
stretched segment lengths (MoorDyn's `GetCurvature`). The moment acts in the
bending plane, p_i = unit(q_{i-1} x q_i): each neighbour gets M_i / l
perpendicular to its segment, towards straightening the line, and node i the
reaction, so that every triplet is force-balanced:

    f- = (EI K_i / l_{i-1}) q_{i-1} x p_i  on node i - 1,
    f+ = (EI K_i / l_i)     q_i x p_i      on node i + 1,
    -(f- + f+)                             on node i.

A line end on a point is a hinge (no moment). A line end on a rod end is clamped:
the line's end tangent t is the rod's axis (pointing from the end node into the
line at end A, out of the line at end B), and the end node carries the curvature
K_0 = 4 sin(theta_0 / 2) / l_0 of the angle between t and the end segment, whose
force pair acts on the end node and its neighbour (the couple on the rod is not
passed on: MoorDyn 2.7 computes no line end moments).

Written without the bending plane's normalisation: with c = q_1 . q_2,
K p = 2 (q_1 x q_2) / (l_sum sqrt((1 + c) / 2)), smooth at theta = 0 (a straight
line gets exactly zero force and finite derivatives), where MoorDyn's
4 sin(theta/2) and unit(q_1 x q_2) each have a kink.
"""

import jax.numpy as jnp

from .._arrays import add_rows, take_rows


def curvature_vectors(q1, q2, l_sum):
    """K p for joints between unit directions `q1`, `q2` `(J, 3)` over the length
    `l_sum` `(J,)`, m: the bending plane's normal scaled by the curvature, 1/m."""
    c = jnp.sum(q1 * q2, axis=-1)
    # c -> -1 is a line folded back on itself: keep the division finite there.
    half = jnp.sqrt(jnp.maximum(0.5 * (1.0 + c), 1e-300))
    return 2.0 * jnp.cross(q1, q2) / (l_sum * half)[:, None]


def bending_forces(qs, lstr, EI_seg, bend, t_a, t_b, n_nodes):
    """Nodal bending forces `(n_nodes, 3)`, N, and the curvature at every node
    `(n_nodes,)`, 1/m (0 at hinged ends).

    **Arguments:** `qs` `(S, 3)` unit segment directions and `lstr` `(S,)` their
    stretched lengths; `EI_seg` `(S,)` the bending stiffness of each segment's line;
    `bend` the network's static bending index arrays (`_Bending`); `t_a`, `t_b`
    the clamped ends' tangents `(Ca, 3)` and `(Cb, 3)` (see the module docstring).
    """
    # static index arrays as slices where they are runs (`take_rows`, `add_rows`);
    # the nodes of the three groups are distinct, so the curvatures add up
    f = jnp.zeros((n_nodes, 3))
    K = jnp.zeros(n_nodes)
    if len(bend.inner_node):
        sp, sn = bend.inner_prev, bend.inner_next
        q_p, q_n, l_p, l_n = (
            take_rows(qs, sp),
            take_rows(qs, sn),
            take_rows(lstr, sp),
            take_rows(lstr, sn),
        )
        Kp = curvature_vectors(q_p, q_n, l_p + l_n)
        EI = take_rows(EI_seg, sp)
        fm = (EI / l_p)[:, None] * jnp.cross(q_p, Kp)
        fp = (EI / l_n)[:, None] * jnp.cross(q_n, Kp)
        m = bend.inner_node
        f = f + add_rows(n_nodes, m - 1, fm) + add_rows(n_nodes, m + 1, fp)
        f = f - add_rows(n_nodes, m, fm + fp)
        K = K + add_rows(n_nodes, m, _norm(Kp))
    if len(bend.clamp_a_node):
        s = bend.clamp_a_seg
        q_s, l_s = take_rows(qs, s), take_rows(lstr, s)
        Kp = curvature_vectors(t_a, q_s, l_s)
        fp = (take_rows(EI_seg, s) / l_s)[:, None] * jnp.cross(q_s, Kp)
        m = bend.clamp_a_node
        f = f + add_rows(n_nodes, m + 1, fp) - add_rows(n_nodes, m, fp)
        K = K + add_rows(n_nodes, m, _norm(Kp))
    if len(bend.clamp_b_node):
        s = bend.clamp_b_seg
        q_s, l_s = take_rows(qs, s), take_rows(lstr, s)
        Kp = curvature_vectors(q_s, t_b, l_s)
        fm = (take_rows(EI_seg, s) / l_s)[:, None] * jnp.cross(q_s, Kp)
        m = bend.clamp_b_node
        f = f + add_rows(n_nodes, m - 1, fm) - add_rows(n_nodes, m, fm)
        K = K + add_rows(n_nodes, m, _norm(Kp))
    return f, K


def _norm(x):
    # The curvature magnitude for the observables (a double-where norm: its
    # gradient is finite at zero).
    sq = jnp.sum(x * x, axis=-1)
    safe = jnp.where(sq > 0, sq, 1.0)
    return jnp.where(sq > 0, jnp.sqrt(safe), 0.0)
