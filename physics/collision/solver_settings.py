"""The contact solver's settings: iterations, substeps and the position correction.

The solver (:mod:`.solver_step`) is the engines' way of handling contact: every contact
of the step is gathered once and all are solved together by sequential impulses
(projected Gauss-Seidel on the velocities, Catto, "Iterative Dynamics with Temporal
Coherence", GDC 2005), with the step cut into ``substeps`` (Box2D v3's "soft step";
Macklin et al., "Small Steps in Physics Simulation", SCA 2019).

Bodies that overlap are pushed apart by one of three position corrections:

- ``"soft"`` (the default): each contact is a stiff, heavily damped spring of natural
  frequency ``contact_hertz`` and damping ratio ``damping_ratio``, integrated implicitly
  with the substep h, which gives the velocity bias and the softened mass of Catto's
  "Soft Constraints" (GDC 2011), as Box2D v3 uses them:

      omega = 2 pi f,  a1 = 2 zeta + h omega,  a2 = h omega a1,
      bias = (omega / a1) s,  mass scale a2 / (1 + a2),  impulse scale 1 / (1 + a2)

  with s < 0 the penetration. It cannot overshoot however stiff, and its push is capped
  at ``push_speed``; a relaxation pass without the bias after the positions are moved
  removes the push velocity again, so a push-out moves bodies without launching them.
- ``"baumgarte"``: the velocity bias beta / h * (s + slop) of Baumgarte, "Stabilization of
  constraints and integrals of motion in dynamical systems" (1972), on the rigid
  constraint; beta = ``baumgarte`` in (0, 1].
- ``"none"``: no position correction; penetration is only prevented, never undone.

Speculative contacts (Catto, "Speculative Contacts", 2013) keep bodies from tunnelling:
a pair a gap s > 0 apart may close at most s / h in a substep, so a fast body arrives
exactly at the surface instead of passing it.
"""

from __future__ import annotations

import dataclasses
import math

import numba

#: position corrections, the default first
CORRECTIONS = ("soft", "baumgarte", "none")
#: the most sweeps over the contacts a step takes, substeps x iterations (each setting alone is
#: then at most this too): the studies use up to 100 x 16; a sweep of the built-in box column
#: takes about 8 us, so a step at this bound takes about a second there, where 10^6 x 10^6
#: would never end
MAX_SWEEPS = 100_000


def is_thread_count(value) -> bool:
    """Whether ``value`` is a thread count Numba can run: an integer from 1 to the threads it started with."""
    return not isinstance(value, bool) and isinstance(value, int) and 1 <= value <= numba.config.NUMBA_NUM_THREADS


def threads_allowed() -> str:
    """What :func:`is_thread_count` allows, in words."""
    return (f"an integer from 1 to {numba.config.NUMBA_NUM_THREADS} (the threads Numba started with on this "
            "machine, NUMBA_NUM_THREADS)")


def sweeps_refusal(iterations: int, substeps: int) -> str:
    """Why ``iterations`` x ``substeps`` over :data:`MAX_SWEEPS` is refused, in one line."""
    return (f"contact solver: iterations x substeps must be at most {MAX_SWEEPS:,} sweeps a step "
            f"(steplab.physics.collision.solver_settings.MAX_SWEEPS), got {iterations:,} x {substeps:,} = "
            f"{iterations * substeps:,}")


@dataclasses.dataclass(frozen=True)
class ContactSolver:
    """Settings of the contact solver (``[collisions.solver]`` in a scene file).

    Parameters
    ----------
    iterations : int
        Gauss-Seidel sweeps over the contacts per substep, in the solve and again in the
        relaxation, and sweeps of the restitution pass at the end of the step (>= 1).
    substeps : int
        Substeps per step (>= 1): forces, contacts and positions are integrated with
        h = dt / substeps; the contacts are found once per step. ``substeps x iterations``
        is at most :data:`MAX_SWEEPS`.
    correction : str
        One of :data:`CORRECTIONS`.
    contact_hertz : float
        Soft correction: natural frequency of the contact spring, Hz (> 0; Box2D's 30).
    damping_ratio : float
        Soft correction: its damping ratio (>= 0; Box2D's 10, overdamped: no bounce).
    baumgarte : float
        Baumgarte correction: the fraction beta in (0, 1] of the penetration undone per substep.
    slop : float
        Penetration left alone, m (>= 0): bodies sunk less than this are not pushed.
    push_speed : float
        The fastest a correction pushes bodies apart, m/s (> 0; Box2D's 3).
    rolling_resistance : float
        Rigid bodies (:mod:`.rigid_solver`): torques up to c_r r P oppose the rolling of a
        sphere or capsule of radius r pressed with the impulse P (>= 0; 0, the default: none).
    threads : int
        Rigid bodies: the threads the step runs its parallel parts on (the narrow phase's
        pairs, and the sweep's domains, :func:`.contact_domains.domain_count`: two from 2,048
        bodies), 1 to ``numba.config.NUMBA_NUM_THREADS``; 1, the default, as Box2D's
        one worker. More threads change no byte of a run (:mod:`.contact_domains`), only its wall time, and
        on a machine whose cores are busy they cost more than they save: each of a step's
        parallel regions waits for its slowest thread's time slice (the 10^4 box pit took 58 to
        1,146 ms a step on 2 threads against 48 to 76 ms on one at load 6 to 11).

    Notes
    -----
    The defaults, 4 substeps of one iteration, are Box2D v3's; ``steplab study contacts``
    finds them as good as 4 x 4 (the column settles to the same 2e-6 in 2 s, the pile keeps
    its energy exactly, the cradle and restitution are the same) at a third of the sweeps.
    """

    iterations: int = 1
    substeps: int = 4
    correction: str = "soft"
    contact_hertz: float = 30.0
    damping_ratio: float = 10.0
    baumgarte: float = 0.2
    slop: float = 0.0
    push_speed: float = 3.0
    rolling_resistance: float = 0.0
    threads: int = 1

    def __post_init__(self):
        for name in ("iterations", "substeps"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"contact solver: {name} must be an integer >= 1, got {value!r}")
        if self.iterations * self.substeps > MAX_SWEEPS:
            raise ValueError(sweeps_refusal(self.iterations, self.substeps))
        if not is_thread_count(self.threads):
            raise ValueError(f"contact solver: threads must be {threads_allowed()}, got {self.threads!r}")
        if self.correction not in CORRECTIONS:
            raise ValueError(f"contact solver: unknown correction {self.correction!r}; valid: {', '.join(CORRECTIONS)}")
        checks = (("contact_hertz", self.contact_hertz > 0, "> 0"),
                  ("damping_ratio", self.damping_ratio >= 0, ">= 0"),
                  ("baumgarte", 0 < self.baumgarte <= 1, "in (0, 1]"),
                  ("slop", self.slop >= 0, ">= 0"),
                  ("push_speed", self.push_speed > 0, "> 0"),
                  ("rolling_resistance", self.rolling_resistance >= 0, ">= 0"))
        for name, ok, allowed in checks:
            value = getattr(self, name)
            if not (math.isfinite(value) and ok):
                raise ValueError(f"contact solver: {name} must be {allowed}, got {value!r}")

    def describe(self) -> str:
        """The settings in a few words: ``"4 substeps x 1 iteration, soft correction"``."""
        def count(n, word):
            return f"{n} {word}" + ("" if n == 1 else "s")

        return (f"{count(self.substeps, 'substep')} x {count(self.iterations, 'iteration')}, "
                f"{self.correction} correction" + (f", {count(self.threads, 'thread')}" if self.threads != 1 else ""))

    def softness(self, h: float) -> tuple[float, float, float]:
        """(bias rate 1/s, mass scale, impulse scale) of the correction for a substep of ``h`` s.

        The soft contact is the implicit (backward Euler) step of a spring k = m omega^2 and
        damper c = 2 m zeta omega acting on the penetration; eliminating the spring force
        from the velocity update gives a velocity constraint with the bias rate omega / a1
        and a mass softened by a2 / (1 + a2), and the accumulated impulse leaking at
        1 / (1 + a2) (Catto 2011). The rigid constraint is (0, 1, 0); Baumgarte's bias
        rate is beta / h.

        Raises ValueError (one line) for a substep h of 0: dt = 5e-324 s in 4 substeps underflows.
        """
        if not h > 0:
            raise ValueError(f"contact solver: the substep h = dt / substeps is {h:g} s (it underflows): a larger dt, "
                             f"or fewer than {self.substeps} substeps")
        if self.correction == "soft":
            omega = 2.0 * math.pi * self.contact_hertz
            a1 = 2.0 * self.damping_ratio + h * omega
            a2 = h * omega * a1
            return omega / a1, a2 / (1.0 + a2), 1.0 / (1.0 + a2)
        if self.correction == "baumgarte":
            return self.baumgarte / h, 1.0, 0.0
        return 0.0, 1.0, 0.0
