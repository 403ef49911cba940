"""Which bodies move together: what an impact on one body changes in the others' motion.

An impulse changes the velocity of the two bodies it acts on. A body whose forces depend
only on its own state (gravity, drag, a constant force, a central attraction) then moves
on as before for everyone else; a body tied to others by *pair forces* (springs,
dampers: the model's forces with index arrays ``i`` and ``j``) pulls them along, and so
on through the whole spring-connected group. The groups are the connected components of
the graph whose edges are the pair forces' pairs (``scipy.sparse.csgraph``).

A force of a kind not known here (a plugin's, a reactive ground contact) might couple
anything to anything: then every body is one group, and every impact re-integrates all
of them (the full re-test's motion, with the incremental loop's pair bookkeeping).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

#: forces acting on each body from its own state only: an impact elsewhere does not change them
PER_BODY_FORCES = frozenset({"gravity", "drag", "constant", "central_gravity"})


class Coupling:
    """The groups of bodies that move together, and the bodies an impact on some of them moves.

    Parameters
    ----------
    model : physics.Model
    """

    def __init__(self, model):
        n = model.n_bodies
        edges_i, edges_j, everything = [], [], False
        for force in model.forces:
            if hasattr(force, "i") and hasattr(force, "j"):
                edges_i.append(np.asarray(force.i, dtype=np.int64).ravel())
                edges_j.append(np.asarray(force.j, dtype=np.int64).ravel())
            elif not (force.constant or force.name in PER_BODY_FORCES):
                everything = True
        self.everything = everything
        if everything or not edges_i:
            self.labels = np.zeros(n, np.int64) if everything else np.arange(n)
        else:
            i, j = np.concatenate(edges_i), np.concatenate(edges_j)
            graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
            self.labels = connected_components(graph, directed=False)[1].astype(np.int64)
        #: each group's bodies, ascending; only groups of more than one body are listed
        order = np.argsort(self.labels, kind="stable")
        sizes = np.bincount(self.labels)
        starts = np.concatenate(([0], np.cumsum(sizes)))
        self._members = {int(g): order[starts[g]:starts[g + 1]] for g in np.flatnonzero(sizes > 1)}

    def moved_by(self, bodies) -> np.ndarray:
        """The bodies whose motion an impulse on ``bodies`` changes: their groups, ascending."""
        if not self._members:  # every body on its own: the impulse moves only its bodies
            return np.unique(bodies) if len(bodies) > 1 and bodies[0] >= bodies[-1] else bodies
        bodies = np.unique(np.asarray(bodies, dtype=np.int64))
        parts = [self._members.get(int(self.labels[b]), np.array([b])) for b in bodies]
        return np.unique(np.concatenate(parts))
