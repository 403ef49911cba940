"""Whether a pair of a translation integrator and a rotation method grows on springs at body-frame points.

:mod:`.attached` steps a pair that composes as one method on the whole system, whose limit is the
integrator's on the coupled stiffest mode (:func:`.stable_dt.scene_mode`). A pair whose stages do
not match (semi-implicit Euler with ``dlm``, velocity Verlet with ``exponential-map``, RK4 with any
rotation method but ``rk4``) steps each system with the other held at the start of the step: the
coupling is first order and not symplectic, and no stability function of either method predicts it.
On ``spring-pendulum`` (k = 1e5 N/m at the cube's corner) every such pair grows at every dt, by
c (omega_max dt)^2 a step: 1.021 a step at dt = 1 ms for semi-implicit Euler with dlm, 1.0018 at
0.3 ms, 1.0002 at 0.1 ms.

What predicts it is the step itself, linearised: one coupled step from the start state and from
states moved along each coordinate (centres, velocities, small turns, angular velocities of the
moving bodies), by central differences. The largest modulus rho of the matrix's eigenvalues is
what the step multiplies the fastest-growing perturbation by; over a run of n steps, rho^n. A
stable pair sits on rho = 1 up to the physics' own slow growth (velocity Verlet with dlm on
spring-pendulum: 1 + 6e-8). Linearised at the start only: a pair that grows there grows, but one
that is quiet there may still meet a stiffer state later.
"""

from __future__ import annotations

import math

import numpy as np
from steplab.physics import quaternion as quat
from steplab.physics.coupled_modes import COUPLED_SIZE, STEP

from .attached import Coupling, composes, coupled_step, first_kept

#: a run over which a perturbation grows by more than this factor (its energy by the square) is warned
#: about: a pair gaining a factor 4 in energy is no longer the system that was asked for
RUN_GROWTH = 2.0


def coupled_growth(model, bodies, integrator, rotation, y0, dt: float) -> float | None:
    """The amplitude's growth per step, rho, of ``integrator`` with ``rotation`` on ``model`` (attached
    forces, its rotating ``bodies``) at the start state ``y0`` (2, N, 3), linearised (see the module);
    inf where a step from the start, or from a state a perturbation away, is not finite; None above
    :data:`.coupled_modes.COUPLED_SIZE` coordinates (the eigenproblem is dense)."""
    y0 = np.asarray(y0, dtype=float)
    q0, omega0 = bodies.orientations, bodies.body_angular_velocities()
    # one model whose lever arms each stage turns in place (none leaves a step): 2x faster, the same bytes
    c = Coupling(model.cast(np, np.float64), bodies, integrator, rotation).turning(q0, omega0)
    free = np.flatnonzero(np.asarray(model.inverse_masses, dtype=float) > 0)
    turning = np.flatnonzero(np.isin(bodies.index, free))  # rows of the rotating bodies that are not pinned
    m, r = len(free), len(turning)
    size = 6 * m + 6 * r
    if size > COUPLED_SIZE:
        return None

    def step(dz):
        """One coupled step from the start moved by ``dz`` (tangent coordinates), in those coordinates
        about the unmoved step's end (``dz`` None: that end itself)."""
        y, q, omega = y0.copy(), q0.copy(), omega0.copy()
        if dz is not None:
            y[0, free] += dz[:3 * m].reshape(-1, 3)
            y[1, free] += dz[3 * m:6 * m].reshape(-1, 3)
            q[turning] = quat.multiply(np, quat.exp(np, dz[6 * m:6 * m + 3 * r].reshape(-1, 3)), q[turning])
            omega[turning] += dz[6 * m + 3 * r:].reshape(-1, 3)
        with np.errstate(all="ignore"):
            y, q, omega, _ = coupled_step(c, 0.0, y, q, omega, first_kept(c, 0.0, y, q, omega), dt)
        if dz is None:
            return y, q, omega
        turn = quat.multiply(np, q[turning], quat.conjugate(np, end[1][turning]))  # the world turn from the end
        turn = 2 * turn[:, 1:] * np.where(turn[:, :1] < 0, -1.0, 1.0)  # its rotation vector, to first order
        return np.concatenate([(y[0, free] - end[0][0, free]).ravel(), (y[1, free] - end[0][1, free]).ravel(),
                               turn.ravel(), (omega[turning] - end[2][turning]).ravel()])

    end = step(None)
    if not all(np.all(np.isfinite(a)) for a in end):
        return math.inf
    scale = np.concatenate([np.full(3 * m, max(1.0, float(np.max(np.abs(y0[0]))))),
                            np.full(3 * m, max(1.0, float(np.max(np.abs(y0[1]))))), np.ones(3 * r),
                            np.full(3 * r, max(1.0, float(np.max(np.abs(omega0), initial=0.0))))])
    jacobian = np.empty((size, size))
    for k in range(size):
        dz = np.zeros(size)
        dz[k] = STEP * scale[k]
        jacobian[:, k] = (step(dz) - step(-dz)) / (2 * dz[k])
    if not np.all(np.isfinite(jacobian)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(jacobian)))) if size else 1.0


def partners(rotation) -> str:
    """The integrators ``rotation`` composes with, for a message."""
    return " or ".join(rotation.composes_with)


def pair_growth(model, bodies, integrator, rotation, y0, dt: float, steps: int) -> dict:
    """How the coupled step of ``integrator`` with ``rotation`` grows over ``steps`` steps of ``dt``.

    A record (JSON as it stands): ``rotation``; ``composes`` (:func:`.attached.composes`);
    ``verdict``, one of "composes" (its limit is the integrator's on the coupled stiffest mode),
    "stays" (within :data:`RUN_GROWTH` over the run), "grows", "not finite" (a step from the start or
    a perturbation away is not) or "not linearised" (more coordinates than :data:`.coupled_modes.COUPLED_SIZE`);
    ``growth_per_step``, rho of :func:`coupled_growth` (None unless measured), and
    ``log10_growth_over_run``, steps log10(rho)."""
    record = {"rotation": rotation.name, "composes": composes(integrator, rotation), "verdict": "composes",
              "growth_per_step": None, "log10_growth_over_run": None}
    if record["composes"]:
        return record
    rho = coupled_growth(model, bodies, integrator, rotation, y0, dt)
    if rho is None or rho == math.inf:
        return record | {"verdict": "not linearised" if rho is None else "not finite"}
    over_run = steps * math.log10(rho) if rho > 0 else -math.inf
    return record | {"verdict": "grows" if over_run > math.log10(RUN_GROWTH) else "stays", "growth_per_step": rho,
                     "log10_growth_over_run": over_run if rho > 0 else None}


def grows(record: dict) -> bool:
    """Whether a :func:`pair_growth` record says the run grows (or cannot step at all)."""
    return record["verdict"] in ("grows", "not finite")


def fold(log10_growth: float) -> str:
    """A growth factor for a message: "1.09e+09-fold", or "10^400-fold" past a float's range."""
    return f"{10 ** log10_growth:.3g}-fold" if log10_growth < 300 else f"10^{log10_growth:.0f}-fold"


def pair_warning(model, bodies, integrator, rotation, y0, dt: float, steps: int) -> str | None:
    """One line when ``integrator`` and ``rotation`` do not compose and their coupled step, linearised at
    the start, grows by more than :data:`RUN_GROWTH` over ``steps`` steps of ``dt`` (or cannot be
    linearised); else None."""
    growth = pair_growth(model, bodies, integrator, rotation, y0, dt, steps)
    if growth["verdict"] in ("composes", "stays"):
        return None
    pair = (f"{integrator.name} with {rotation.name}: their stages do not match ({rotation.name} composes with "
            f"{partners(rotation)}), so on springs at body-frame points each steps with the other held")
    if growth["verdict"] == "not linearised":  # too many coordinates: the declaration alone
        return f"{pair}, first order and not symplectic: it may gain energy at any dt; see steplab check"
    if growth["verdict"] == "not finite":
        return f"{pair}, and at dt = {dt:g} s its step about the start state is already not finite"
    return (f"{pair}: linearised at the start the step grows a perturbation {growth['growth_per_step']:.6g}-fold a "
            f"step at dt = {dt:g} s, {fold(growth['log10_growth_over_run'])} over the run's {steps} steps; pair "
            f"{rotation.name} with {partners(rotation)}, or see steplab check")
