"""The largest stable dt of each fixed-step method on a model, predicted before running.

An explicit method is stable on a linear mode of frequency omega and damping ratio zeta
while omega dt stays under the method's own limit on the damped oscillator
(:meth:`Stepper.stability_limit`, from its stability function or amplification matrix).
Every mode of the linearised model must be stable, and the stiffest one
(:func:`steplab.physics.modes.stiffest_mode`, omega_max) fails first, so

    dt_max = stability_limit(zeta) / omega_max.

With proportional damping (the soft bodies' dampers sit on their springs) the stiffest
mode is also the most damped one, and the damped limit is the one a run meets; the
undamped limit is reported beside it (the textbook 2 / omega_max of symplectic Euler).
A model without a restoring force (no springs) has no oscillating mode and no limit.
"""

from __future__ import annotations

import dataclasses

from steplab.physics.modes import NonFiniteModelError, StiffestMode, stiffest_mode

from .base import Stepper

#: a one-step spectral radius above 1 + this counts as growth (the symplectic methods sit
#: exactly on |eigenvalue| = 1 below their limit, up to round-off)
GROWTH_TOLERANCE = 1e-12


@dataclasses.dataclass(frozen=True)
class StableStep:
    """One method's predicted limits on one model (None: no limit; 0: unstable at every dt)."""

    integrator: str
    omega_dt_max: float | None  # undamped
    dt_max: float | None
    omega_dt_max_damped: float | None  # at the stiffest mode's damping ratio
    dt_max_damped: float | None

    def stable(self, dt: float) -> bool:
        """Whether ``dt`` is within the damped limit (the one a run meets)."""
        return self.dt_max_damped is None or dt <= self.dt_max_damped


def _dt(limit: float | None, omega: float) -> float | None:
    return None if limit is None else limit / omega


def stable_step(mode: StiffestMode, stepper: Stepper) -> StableStep:
    """The largest stable dt of ``stepper`` on a model whose stiffest mode is ``mode``."""
    if mode.omega is None:
        return StableStep(stepper.name, None, None, None, None)
    undamped = stepper.stability_limit(0.0)
    damped = undamped if mode.damping_ratio == 0 else stepper.stability_limit(mode.damping_ratio)
    return StableStep(stepper.name, undamped, _dt(undamped, mode.omega), damped, _dt(damped, mode.omega))


def scene_mode(model, q, bodies=None, derivative: str = "jvp") -> StiffestMode:
    """The stiffest mode of ``model`` at positions ``q``: with springs or dampers at body-frame points on
    the rotating ``bodies``, of the translation and the rotation together
    (:func:`steplab.physics.coupled_modes.coupled_stiffest_mode`; the lever arms held, a turn would
    be no degree of freedom and the mode too slow), else :func:`steplab.physics.modes.stiffest_mode`."""
    from steplab.physics.attachments import attached_forces

    if bodies is not None and attached_forces(model):
        from steplab.physics.coupled_modes import coupled_stiffest_mode

        return coupled_stiffest_mode(model, bodies, q)
    return stiffest_mode(model, q, derivative=derivative)


def stable_steps(model, q, steppers, bodies=None) -> tuple[StiffestMode, list[StableStep]]:
    """The stiffest mode of ``model`` at positions ``q`` (:func:`scene_mode`) and each stepper's limits on it."""
    mode = scene_mode(model, q, bodies)
    return mode, [stable_step(mode, s) for s in steppers if isinstance(s, Stepper)]


def dt_warning(model, q, stepper, dt: float, bodies=None) -> str | None:
    """One line when ``dt`` exceeds the largest stable dt of ``stepper`` on ``model``, else None.

    Cheap enough to run before every ``steplab run``: the mode by central differences
    (milliseconds, no compilation), then one spectral radius at omega_max dt; the limit
    itself is searched only when that step already grows. Silent for a model without
    springs or with forces that overflow at the initial state, for a solver and for an
    unconditionally stable method. A method unstable at every dt (explicit Euler on an
    undamped mode) is warned about too, with its growth per step: slow growth is still growth.
    """
    if not isinstance(stepper, Stepper):
        return None
    try:
        mode = scene_mode(model, q, bodies, derivative="difference")
    except NonFiniteModelError:  # the run itself will say what is wrong
        return None
    if mode.omega is None or stepper.spectral_radius(mode.omega * dt, mode.damping_ratio) <= 1 + GROWTH_TOLERANCE:
        return None
    limit = stable_step(mode, stepper)
    if limit.dt_max_damped is None:  # no limit
        return None
    damped = f", damping ratio {mode.damping_ratio:.3g}" if mode.damping_ratio else ""
    if limit.dt_max_damped == 0:  # unstable at every dt: the amplitude's growth factor per step says how fast
        growth = stepper.spectral_radius(mode.omega * dt, mode.damping_ratio)
        return (f"dt = {dt:g} s exceeds the largest stable dt of {stepper.name} on this scene: there is none, it "
                f"grows at every dt (stiffest mode: omega_max = {mode.omega:.4g} rad/s{damped}; each step "
                f"multiplies its amplitude by {_factor(growth)}, its energy by {_factor(growth * growth)}); see "
                "steplab check")
    hint = (f" (a dt in milliseconds? {dt:g} ms is --dt {dt / 1000:g})"
            if dt >= 1 and dt / 1000 <= limit.dt_max_damped else "")
    return (f"dt = {dt:g} s exceeds the largest stable dt of {stepper.name} on this scene, "
            f"{limit.dt_max_damped:.3g} s (stiffest mode: omega_max = {mode.omega:.4g} rad/s{damped}; "
            f"omega dt = {mode.omega * dt:.3g} > {limit.omega_dt_max_damped:.4g}): the run will blow up{hint}; "
            "see steplab check")


def _factor(growth: float) -> str:
    """A growth factor per step as a reader can tell it from 1: explicit Euler on kepler's orbit grows by
    1.00016 a step, which four digits print as "1"."""
    return f"{growth:.4g}" if growth >= 1.001 else f"1 + {growth - 1:.3g}"
