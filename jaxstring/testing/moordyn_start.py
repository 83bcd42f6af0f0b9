"""A deck's scene started where MoorDyn starts it (test support).

MoorDyn draws each line's initial profile as an elastic catenary, or as a straight
line where its catenary solve fails; jaxstring starts a taut line straight. To
compare the two codes' dynamics from one state (the tripod deck's lines start up
to 4 cm apart), `from_moordyn_nodes` puts MoorDyn's initial node positions into
the scene's initial state, and `point_nodes` gives the node each of MoorDyn's
points is (to compare point positions). `from_moordyn_nodes` needs the `moordyn`
package (the ``bench`` extra).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np


def from_moordyn_nodes(scene, moordyn, system):
    """`scene` (a MoorDyn deck's `read_moordyn` scene) with every free node's
    position taken from MoorDyn's `system` (created from the same deck and
    initialised); velocities and everything else as they were.

    **Arguments:** `scene`; `moordyn`: the `moordyn` module; `system`: its
    initialised system.

    **Returns:** the scene with the new initial state."""
    m = scene.model
    top = m.topology
    rows, slot = np.asarray(top.tri_rows), np.asarray(top.body)
    y0 = np.array(scene.y0)
    for k in range(m.n_lines):
        line = moordyn.GetLine(system, k + 1)
        for i, n in enumerate(m.line_nodes(k)):
            if slot[n] < len(rows):
                y0[rows[slot[n]], :3] = moordyn.GetLineNodePos(line, i)
    return eqx.tree_at(lambda s: s.y0, scene, jnp.asarray(y0))


def point_nodes(model) -> list:
    """The node index of each point of a deck's `model`, in the deck's order (a
    point is the end node of the lines attached to it): index the `nodes`
    observable with it for the points' positions."""
    at = {}
    for k, (a, b) in enumerate(model.attach):
        idx = model.line_nodes(k)
        at.setdefault(a, idx[0])
        at.setdefault(b, idx[-1])
    return [at[i] for i in range(len(model.points))]
