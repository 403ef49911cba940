"""MuJoCo: the scene's MJCF (:mod:`.mjcf`) compiled and stepped with ``mj_step``.

The state is read and written through the free joints: ``qpos`` holds each moving body's
position and a unit quaternion (w, x, y, z), ``qvel`` its linear and angular velocity
(spheres: the rotation never changes where a centre goes, and starts at rest). A rotating
body's orientation is its ``qpos`` quaternion as steplab's (body to world); the angular
part of a free joint's ``qvel`` is in the *body* frame, omega_body = R^T omega_world, so it
is rotated on the way in and out.
"""

from __future__ import annotations

import numpy as np

from steplab.physics import quaternion as quat

from .base import EngineRun, Setting, body_indices, require, scene_parts, version
from .mjcf import ENGINE, MujocoOption, mjcf

#: why MuJoCo's bounce is not eps^2 (the drop test's explanation, from MuJoCo's documented contact model)
SOFT_CONTACT = ("soft contact: eps becomes the damping ratio of a spring-damper contact of natural frequency "
                "1 / (2 dt), the stiffest MuJoCo integrates; its impedance (solimp) softens it a little")


def _quiet(mujoco) -> None:
    """MuJoCo's warnings ("the simulation is unstable") off stderr: the run's own checks report."""
    mujoco.set_mju_user_warning(lambda message: None)


class MujocoRun(EngineRun):
    engine = "mujoco"
    display_name = "MuJoCo"
    colour = "tab:blue"
    precision = "float64"
    package = distribution = "mujoco"
    study_settings = (
        Setting("mujoco-euler", "MuJoCo Euler", {"integrator": "Euler"}, False, "semi-implicit-euler", SOFT_CONTACT),
        Setting("mujoco-rk4", "MuJoCo RK4", {"integrator": "RK4"}, False, "rk4",
                "the same contact bounces higher under RK4: what a spring-damper contact returns depends on how "
                "the step integrates it, and the mapping eps -> damping ratio is the continuous one's"),
        Setting("mujoco-implicit", "MuJoCo implicit", {"integrator": "implicit"}, False, "implicit-damping-euler",
                SOFT_CONTACT),
        Setting("mujoco-implicitfast", "MuJoCo implicitfast", {"integrator": "implicitfast"}, False,
                "implicit-damping-euler", SOFT_CONTACT),
        Setting("mujoco-discrete", "MuJoCo discrete", {"integrator": "discrete"}, False, "implicit-euler",
                "the contact spring is integrated by backward Euler as well, whose numerical damping takes "
                "a large part of the bounce"),
    )

    rotation_settings = (
        Setting("mujoco-euler", "MuJoCo Euler", {"integrator": "Euler"}, None, "exponential-map",
                "omega from the Coriolis term at the start of the step, then q exp(h omega) with the new omega "
                "(mj_integratePos)"),
        Setting("mujoco-implicitfast", "MuJoCo implicitfast", {"integrator": "implicitfast"}, None,
                "implicit-gyroscopic", "the gyroscopic term's derivative is in the step's matrix: one Newton step on "
                "omega, then the exponential map; it damps the tumbling"),
        Setting("mujoco-implicit", "MuJoCo implicit", {"integrator": "implicit"}, None, "implicit-gyroscopic",
                "the full derivative of the forces, which on a free body is that of the gyroscopic term: as "
                "implicitfast"),
        Setting("mujoco-rk4", "MuJoCo RK4", {"integrator": "RK4"}, None, None,
                "RK4 on omega, but each stage's orientation is q exp(c h omega_stage) and the step's q exp(h "
                "sum b omega), not RK4 on the quaternion's components: 4th order, not steplab's rk4"),
    )

    stack_settings = (
        Setting("mujoco-newton", "MuJoCo Newton (default)", {"solver": "Newton"}, None, None,
                "MuJoCo's default solver: Newton's method on the soft contacts' convex problem"),
        Setting("mujoco-pgs", "MuJoCo PGS", {"solver": "PGS"}, None, None,
                "projected Gauss-Seidel on the dual problem, the sequential-impulse family"),
        Setting("mujoco-newton-substeps", "MuJoCo Newton, 4 substeps", {"solver": "Newton", "substeps": 4}, None,
                None, "each step as 4 MuJoCo steps of dt/4: the contact spring, as stiff as MuJoCo integrates "
                "(natural frequency 1 / (2 timestep)), is 16 times stiffer, so a stack sinks 16 times less"),
    )

    @classmethod
    def integrator_stepping_as(cls, method: str) -> str | None:
        """MuJoCo's integrator that steps as steplab's ``method`` does (what its settings declare;
        of two, the later: implicitfast), or None."""
        return {s.equals: s.options["integrator"] for s in cls.study_settings if s.equals}.get(method)

    def __init__(self, model, collisions=None, dt: float = 0.01, y0=None, bodies=None, substeps: int = 1,
                 **option):
        """The scene compiled by MuJoCo; ``option``: the keywords of :class:`.mjcf.MujocoOption`
        (``integrator``, ``solver``, ``iterations``, ``jacobian``); each step is ``substeps``
        MuJoCo steps of dt / substeps."""
        option = MujocoOption(**option)
        mujoco = require("mujoco", ENGINE)
        super().__init__(scene_parts(model, collisions, ENGINE), model, bodies)
        n = self.parts.n
        y0 = np.zeros((2, n, 3)) if y0 is None else np.asarray(y0, float)
        self._mujoco = mujoco
        # substeps: MuJoCo's own step is dt / substeps, its contacts stiffened to match (mjcf)
        self.substeps = int(substeps)
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {substeps}")
        self.xml = mjcf(model, y0, dt / self.substeps, collisions, option, bodies=bodies)
        _quiet(mujoco)
        self.model = mujoco.MjModel.from_xml_string(self.xml)
        # MuJoCo puts a diverging simulation back at its start (auto-reset) and carries on;
        # the measurements must see the divergence instead
        self.model.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_AUTORESET
        self.data = mujoco.MjData(self.model)
        self.moving = body_indices(self.parts)
        # each rotating body's row among the free joints (None: pinned, it never turns)
        row = {int(i): r for r, i in enumerate(self.moving)}
        self._rows = [row.get(shape.body) for shape in self.rigid]
        self._dt = dt
        self._y = y0.copy()
        solver_text = "" if option.solver is None else f", {option.solver}" + (
            f", {option.iterations} iterations" if option.iterations else "")
        solver_text += f", {self.substeps} substeps" if self.substeps > 1 else ""
        self.settings = f"MuJoCo {version('mujoco')} {option.integrator}{solver_text}"
        # geom id -> body index or shape name, for the contact log
        self._geoms = {}
        for g in range(self.model.ngeom):
            name = mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, g)
            self._geoms[g] = int(name[4:]) if name and name.startswith("body") and name[4:].isdigit() else name

    def set_state(self, y) -> None:
        mujoco, m, d = self._mujoco, self.model, self.data
        mujoco.mj_resetData(m, d)
        self._y = np.array(y, dtype=float)
        k = len(self.moving)
        qpos = np.zeros((k, 7))
        qpos[:, :3], qpos[:, 3] = self._y[0, self.moving], 1.0
        qvel = np.zeros((k, 6))
        qvel[:, :3] = self._y[1, self.moving]
        d.qpos[:], d.qvel[:] = qpos.ravel(), qvel.ravel()

    def set_rotation(self, orientations, angular_velocities) -> None:
        k = len(self.moving)
        qpos, qvel = self.data.qpos.reshape(k, 7), self.data.qvel.reshape(k, 6)  # views of MuJoCo's arrays
        q, omega = np.asarray(orientations, float), np.asarray(angular_velocities, float)
        self._fixed = (q, omega)
        for j, row in enumerate(self._rows):
            if row is not None:
                qpos[row, 3:] = q[j]
                qvel[row, 3:] = quat.rotate_inverse(np, q[j], omega[j])

    def rotation(self) -> tuple[np.ndarray, np.ndarray]:
        k = len(self.moving)
        qpos, qvel = self.data.qpos.reshape(k, 7), self.data.qvel.reshape(k, 6)
        q, omega = (a.copy() for a in self._fixed)
        for j, row in enumerate(self._rows):
            if row is not None:
                q[j] = qpos[row, 3:]
                omega[j] = quat.rotate(np, q[j], qvel[row, 3:])
        return q, omega

    def step(self, dt: float) -> None:
        if dt != self._dt:
            self._dt = dt
            self.model.opt.timestep = dt / self.substeps
        if self.substeps == 1:
            self._mujoco.mj_step(self.model, self.data)
        else:
            self._mujoco.mj_step(self.model, self.data, nstep=self.substeps)

    def run(self, steps: int) -> None:
        """``steps`` steps in one call (MuJoCo's own loop, for timing)."""
        self._mujoco.mj_step(self.model, self.data, nstep=steps * self.substeps)

    def state(self) -> np.ndarray:
        k = len(self.moving)
        self._y[0, self.moving] = self.data.qpos.reshape(k, 7)[:, :3]
        self._y[1, self.moving] = self.data.qvel.reshape(k, 6)[:, :3]
        return self._y.copy()

    def touching(self) -> dict:
        out = {}
        for c in self.data.contact[: self.data.ncon]:
            a, b = self._geoms.get(int(c.geom1)), self._geoms.get(int(c.geom2))
            normal = np.array(c.frame[:3])  # from geom1 to geom2
            if isinstance(a, int):
                out[(a, b)] = normal
            elif isinstance(b, int):
                out[(b, a)] = -normal
        return out
