"""NVIDIA Newton (on Warp) for spring-mass scenes: particles, damped springs, pinned particles, gravity.

- Each body is a Newton particle of its mass; a pinned body is a particle of mass 0, which
  Newton's integrators neither accelerate nor move (as steplab's inverse mass 0). Particle
  radii are 0: Newton's particle-particle contacts stay off, as steplab's scene has none.
- A spring and damper on a pair is one Newton spring (``ke`` the stiffness, ``kd`` the
  damping along the axis, steplab's rest length); gravity is the model's.
- The solvers: ``semi-implicit`` (SolverSemiImplicit: v += dt a(q, v), q += dt v),
  ``xpbd`` (SolverXPBD: compliance 1 / (ke dt^2), damping gamma = kd / (ke dt), as
  steplab's; its sweep over the springs is Jacobi, every correction from the same
  positions, summed, where steplab's is Gauss-Seidel) and ``vbd`` (SolverVBD: block
  descent on implicit Euler's energy per graph colour), ``iterations`` sweeps per step.
- Warp computes in float32. It compiles its kernels on first use (a minute on two cores)
  and keeps them in its cache: the user cache (~/.cache/warp/<version>), or
  ``WARP_CACHE_PATH``.

No collisions (Newton's contacts have no counterpart in steplab's collision world here),
no other forces. The extra: ``pip install steplab[newton]`` (newton and warp-lang).
"""

from __future__ import annotations

import contextlib
import importlib.util
import math
import os

import numpy as np

from .base import EngineNotInstalledError, EngineRun, Setting, UnsupportedFeatureError, require, scene_parts, version

ENGINE = "Newton"
INSTALL_HINT = "pip install steplab[newton]"
#: Newton's solver class by the adapter's name for it
SOLVERS = {"semi-implicit": "SolverSemiImplicit", "xpbd": "SolverXPBD", "vbd": "SolverVBD"}


def _load():
    """warp and newton, imported and Warp initialised without its greeting, or EngineNotInstalledError."""
    if not NewtonRun.available():
        raise EngineNotInstalledError(f"{ENGINE} needs the Python packages 'newton' and 'warp-lang', which are "
                                      f"not installed ({INSTALL_HINT})")
    wp = require("warp", ENGINE)
    newton = require("newton", ENGINE)
    wp.config.log_level = wp.LOG_WARNING  # no greeting, no line per compiled module
    with _stderr_to_null():  # Warp's C code warns that it finds no CUDA driver (it runs on the CPU)
        wp.init()  # once: later calls return at once
    return wp, newton


@contextlib.contextmanager
def _stderr_to_null():
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class NewtonRun(EngineRun):
    """A steplab spring-mass scene as a Newton model of particles and springs, stepped by one Newton solver."""

    engine = "newton"
    display_name = "NVIDIA Newton (Warp, CPU)"
    colour = "tab:olive"
    precision = "float32"
    package = distribution = "newton"
    contacts = False
    study_settings = (
        Setting("newton-semi-implicit", "Newton SolverSemiImplicit", {"solver": "semi-implicit"}, None,
                "semi-implicit-euler", "none: the same step, in float32"),
        Setting("newton-xpbd", "Newton SolverXPBD", {"solver": "xpbd", "iterations": 1}, None, "xpbd",
                "a Jacobi sweep (every spring corrected from the same positions, the corrections summed) where "
                "steplab's is Gauss-Seidel: the same step on a single spring, another one on a cloth"),
        Setting("newton-vbd", "Newton SolverVBD", {"solver": "vbd", "iterations": 1}, None, "vbd",
                "block descent on implicit Euler's energy per graph colour, as steplab's vbd, in another "
                "colour order and initial guess (1.4e-2 apart at one iteration); with 16 to 256 iterations it "
                "stays 4e-4 to 5e-4 from implicit Euler on the cloth, where steplab's vbd converges to 1e-13: "
                "float32 positions, not the method. It solves for x and takes v = (x - x_prev) / h, so v carries "
                "the round-off of x (eps32 |x|, |x| about 2 m) over h: about 1e-4 m/s a step at h = 2 ms. The gap "
                "grows with the cloth's distance from the origin and as 1 / h; damping and iterations leave it"),
    )

    @classmethod
    def available(cls) -> bool:
        return all(importlib.util.find_spec(package) is not None for package in ("newton", "warp"))

    def __init__(self, model, collisions=None, dt: float = 0.01, solver: str = "xpbd", iterations: int = 1,
                 y0=None):
        if solver not in SOLVERS:
            raise ValueError(f"newton: unknown solver {solver!r}; valid: {', '.join(SOLVERS)}")
        if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) or iterations < 1:
            raise ValueError(f"newton: iterations must be a whole number >= 1, got {iterations!r}")
        if collisions is not None and collisions.detector != "none":
            raise UnsupportedFeatureError(f"collisions: the {ENGINE} adapter runs spring-mass scenes without "
                                          "contacts")
        super().__init__(scene_parts(model, None, ENGINE))
        parts = self.parts
        for i, j, k, rest, _ in parts.links:
            if rest is None and solver == "xpbd":
                raise UnsupportedFeatureError(f"a damper without a spring ({parts.names[i]}, {parts.names[j]}): "
                                              f"{ENGINE}'s SolverXPBD damps only beside a spring")
            if math.isinf(k) and solver != "xpbd":
                raise UnsupportedFeatureError(f"an inextensible spring ({parts.names[i]}, {parts.names[j]}): "
                                              f"{ENGINE}'s SolverXPBD takes it, its {SOLVERS[solver]} does not")
        wp, newton = _load()
        self._wp = wp
        y0 = np.zeros((2, parts.n, 3)) if y0 is None else np.asarray(y0, float)
        builder = newton.ModelBuilder(up_axis=newton.Axis.Z, gravity=tuple(float(g) for g in parts.gravity))
        masses = np.where(parts.pinned, 0.0, parts.masses)
        builder.add_particles([tuple(p) for p in y0[0]], [tuple(u) for u in y0[1]], masses.tolist(),
                              radius=[0.0] * parts.n)
        for i, j, k, _, c in parts.links:
            builder.add_spring(i, j, k, c, 0.0)
        # steplab's rest lengths, not the start's distances that add_spring measures
        builder.spring_rest_length = [0.0 if rest is None else rest for *_, rest, _ in parts.links]
        if solver == "vbd":
            builder.color()  # VBD sweeps the particles colour by colour
        self.model = builder.finalize(device="cpu")
        self.model.particle_grid = None  # no particle-particle contacts (semi-implicit's hash grid)
        cls = getattr(newton.solvers, SOLVERS[solver])
        self.solver = cls(self.model) if solver == "semi-implicit" else cls(self.model, iterations=iterations)
        self.control = self.model.control()
        self._states = [self.model.state(), self.model.state()]
        sweeps = "" if solver == "semi-implicit" else f", {iterations} iteration{'s' * (iterations > 1)}"
        self.settings = f"Newton {version('newton')} {SOLVERS[solver]}{sweeps} (Warp {version('warp-lang')}, CPU)"

    def set_state(self, y) -> None:
        y = np.asarray(y, dtype=np.float32)
        for state in self._states:  # both: Newton's solvers leave a pinned particle's slot unwritten
            state.particle_q.assign(y[0])
            state.particle_qd.assign(y[1])

    def step(self, dt: float) -> None:
        state_in, state_out = self._states
        state_in.clear_forces()
        self.solver.step(state_in, state_out, self.control, None, dt)
        self._states = [state_out, state_in]

    def run(self, steps: int, dt: float) -> None:
        """``steps`` steps, then wait for Warp (for timing)."""
        for _ in range(steps):
            self.step(dt)
        self._wp.synchronize()

    def state(self) -> np.ndarray:
        state = self._states[0]
        return np.stack([state.particle_q.numpy(), state.particle_qd.numpy()]).astype(float)


#: Newton's rigid-body solvers a free body runs under (SolverMuJoCo needs mujoco_warp, which the
#: extra leaves out); each with its angular damping off
RIGID_SOLVERS = ("SolverSemiImplicit", "SolverXPBD", "SolverFeatherstone")


def free_body_rotation(inertia, omega0, dt: float, n_steps: int, solver: str = "SolverXPBD"):
    """A free rigid body of principal moments ``inertia`` (3,), kg m^2, spun at ``omega0`` (3,)
    rad/s from the identity orientation, no gravity, ``n_steps`` steps of ``dt`` in Newton's ``solver``.

    The body is Newton's ``add_body`` (a free joint); SolverFeatherstone steps the joint's
    coordinates, the others the body's, and both are read back through the body. Returns
    (q (n_steps + 1, 4), unit quaternions (w, x, y, z); omega (n_steps + 1, 3), body frame), as
    :func:`steplab.integrators.rotation.simulate_rotation` for one body.
    """
    if solver not in RIGID_SOLVERS:
        raise ValueError(f"newton: unknown rigid-body solver {solver!r}; valid: {', '.join(RIGID_SOLVERS)}")
    from steplab.physics import quaternion as quat

    wp, newton = _load()
    builder = newton.ModelBuilder(gravity=(0.0, 0.0, 0.0))
    builder.add_body(mass=1.0, inertia=wp.mat33(*np.diag(np.asarray(inertia, float)).ravel()))
    model = builder.finalize(device="cpu")
    states = [model.state(), model.state()]
    twist = np.zeros(6, np.float32)
    twist[3:] = omega0  # the free joint's (v, omega), world frame: the body frame at the identity
    for state in states:
        state.joint_qd.assign(twist)
        newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    step = getattr(newton.solvers, solver)(model, angular_damping=0.0)
    control = model.control()
    q, omega = np.empty((n_steps + 1, 4)), np.empty((n_steps + 1, 3))
    for k in range(n_steps + 1):
        if k:
            states[0].clear_forces()
            step.step(states[0], states[1], control, None, dt)
            states.reverse()
            if solver == "SolverFeatherstone":
                newton.eval_fk(model, states[0].joint_q, states[0].joint_qd, states[0])
        x, y, z, w = states[0].body_q.numpy()[0, 3:7]  # Warp's quaternions are (x, y, z, w)
        q[k] = w, x, y, z
        omega[k] = quat.rotate_inverse(np, q[k], states[0].body_qd.numpy()[0, 3:].astype(float))
    return q, omega
