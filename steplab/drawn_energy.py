"""The energy each panel of ``steplab animate`` draws: a run's mechanical energy at each saved state, the
rotating bodies' spin and the springs at their lever arms included (the energy ``steplab run`` reports), and
each run's change from its start in one unit for all the panels.
"""

from __future__ import annotations

import numpy as np


def attached_energies(model, traj, rotation) -> np.ndarray:
    """The energy (K,) at each saved state of a run of a model with springs or dampers at body-frame
    points, J: the centres' kinetic energy, the rotating bodies' 1/2 omega . I omega, and the potential
    with every lever arm R(q) r at that state's orientations (``rotation``, a RotationTrajectory at the
    run's saved times). At the last state it is the ``energy_end`` of ``steplab run``."""
    from steplab.integrators.scene_rotation import rotation_arrays
    from steplab.physics.attachments import model_at

    arrays = rotation_arrays(rotation, model.n_bodies)
    orientations, spins = arrays["orientations"], arrays["angular_velocities"]
    return np.array([float(model_at(model, orientations[k], spins[k]).energy(np.asarray(y, float), rotation.at(k)))
                     for k, y in enumerate(traj.y)])



def drawn_energies(model, traj, rotation=None) -> np.ndarray:
    """The energy (K,) the energy panel draws at each saved state of ``traj``, J: ``model.energy`` (the
    centres' kinetic and the potential energy); with ``rotation`` (the run's RotationTrajectory at its
    saved times) the rotating bodies' 1/2 omega . I omega too, and for a model with springs or dampers
    at body-frame points their lever arms at each state (:func:`attached_energies`). It is the energy
    ``steplab run`` reports: at the last state, its ``energy_end``."""
    from steplab.physics.attachments import attached_forces

    if rotation is None:
        return np.array([float(model.energy(y)) for y in traj.y])
    if attached_forces(model):
        return attached_energies(model, traj, rotation)
    return np.array([float(model.energy(np.asarray(y, float), rotation.at(k))) for k, y in enumerate(traj.y)])


def energy_changes(energies: list[np.ndarray]) -> tuple[list[np.ndarray], str]:
    """Each run's energy change from its start: in % of the initial energy, or in J when it is 0."""
    e0 = energies[0][0]
    if e0 == 0 or not np.isfinite(e0):
        return [e - e[0] for e in energies], "J"
    return [100 * (e - e[0]) / abs(e0) for e in energies], "% of the initial"
