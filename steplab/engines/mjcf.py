"""A steplab scene as MJCF, MuJoCo's model file (``steplab export SCENE --to mjcf``).

Written from the scene alone (MuJoCo need not be installed):

- a moving body is a ``<body>`` with a free joint and a sphere geom of its mass and radius
  (its initial position and velocity are the keyframe ``initial``); a pinned body is a site
  (and, with collisions, a sphere geom) of the world body;
- a rotating body (the scene's ``rigid_bodies``) gets the geom of its shape (box, capsule,
  cylinder or sphere, :func:`.base.rigid_shapes`) and an ``<inertial>`` with its mass and
  principal moments (``diaginertia``, the body frame being the principal frame); its
  orientation is the body's ``quat`` and the keyframe's, its angular velocity the free joint's
  angular ``qvel``, which MuJoCo keeps in the *body* frame (R^T omega_world);
- gravity is ``<option gravity>``; a spring and/or damper between two bodies is a spatial
  tendon between their sites with ``stiffness``, ``springlength`` and ``damping``: its force
  acts along the line between the centres, k (l - l_rest) + c dl/dt, exactly steplab's
  Hooke spring and axial damper;
- planes, boxes and oriented boxes are static geoms; restitution, which MuJoCo's soft
  contacts do not have, becomes the damping ratio of the contact's spring-damper, the one
  whose bounce keeps eps of the approach speed (:func:`damping_ratio`); friction mu is the
  geoms' sliding friction (mu = 0: frictionless contacts, ``condim="1"``); the contact
  spring is as stiff as MuJoCo integrates stably at the step, a natural frequency of
  1 / (2 dt) (:data:`CONTACT_STEPS`);
- no ``[collisions]`` (or the detector "none"): contacts are disabled.
"""

from __future__ import annotations

import dataclasses
import math
from xml.sax.saxutils import quoteattr

import numpy as np

from steplab.physics import Dampers, Gravity, Springs
from steplab.physics import quaternion as quat
from steplab.physics.collision import Box, OrientedBox, Plane

from .base import rigid_shapes, scene_parts

ENGINE = "MuJoCo"
#: MuJoCo's integrators by the name of its ``integrator`` option
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast", "discrete")
#: the contact's natural period over the step, 1 / (omega_0 dt): MuJoCo's own lower bound on
#: its time constant (a stiffer contact spring is unstable at the step)
CONTACT_STEPS = 2
#: the damping ratio of a perfectly elastic contact (eps = 1): MuJoCo needs one above 0
SMALLEST_DAMPING_RATIO = 1e-9
#: MuJoCo's arena per thousand balls, MB (enough for each ball touching a few others)
MEGABYTES_PER_1000_BALLS = 20


def damping_ratio(restitution: float) -> float:
    """The damping ratio zeta of a spring-damper contact that bounces with ``restitution``.

    A mass on a linear spring-damper leaves after half a damped period with its speed
    multiplied by exp(-zeta pi / sqrt(1 - zeta^2)); setting that to eps gives
    zeta = -ln eps / sqrt(pi^2 + ln^2 eps) (eps = 1: zeta = 0, raised to
    SMALLEST_DAMPING_RATIO; eps = 0: zeta = 1, critical).
    """
    if restitution <= 0:
        return 1.0
    log = math.log(restitution)
    # MuJoCo reads a zero damping ratio as a "mixed" solref and replaces it by its default
    return max(-log / math.sqrt(math.pi**2 + log**2), SMALLEST_DAMPING_RATIO)


@dataclasses.dataclass(frozen=True)
class MujocoOption:
    """MJCF's ``<option>`` as steplab sets it: MuJoCo's ``integrator`` (one of
    :data:`INTEGRATORS`) and its constraint solver's ``solver``, ``iterations`` and ``jacobian``
    (None: MuJoCo's default)."""

    integrator: str = "Euler"
    solver: str | None = None
    iterations: int | None = None
    jacobian: str | None = None


def _vec(values) -> str:
    return " ".join(repr(float(x)) for x in values)


def _geom(shape) -> str:
    """MuJoCo's geom type and size of a rotating body (:class:`.base.RigidShape`)."""
    if shape.shape == "box":
        return f'type="box" size="{_vec(shape.half_extents)}"'
    if shape.shape in ("capsule", "cylinder"):
        return f'type="{shape.shape}" size="{_vec(shape.half_extents[[0, 2]])}"'
    return f'type="sphere" size="{float(shape.radius)!r}"'


def mjcf(model, y0, dt: float, collisions=None, option: MujocoOption = MujocoOption(), name: str = "steplab",
         bodies=None) -> str:
    """The MJCF text of a scene: ``model`` and ``y0`` (2, N, 3), the step ``dt``, ``collisions``,
    the rotating ``bodies`` (a :class:`steplab.physics.rigid_body.RigidBodies`, or None).

    ``option`` is MuJoCo's integrator and constraint solver (default: Euler and MuJoCo's
    solver). UnsupportedFeatureError for a scene feature MJCF cannot hold (another force than
    gravity, springs and dampers).
    """
    integrator = option.integrator
    if integrator not in INTEGRATORS:
        raise ValueError(f"unknown MuJoCo integrator {integrator!r}; valid: {', '.join(INTEGRATORS)}")
    parts = scene_parts(model, collisions, ENGINE, forces=(Gravity, Springs, Dampers),
                        shapes=(Plane, Box, OrientedBox))
    q, v = np.asarray(y0[0], float), np.asarray(y0[1], float)
    contacts = parts.collisions is not None
    attributes = f'timestep="{float(dt)!r}" gravity="{_vec(parts.gravity)}" integrator="{integrator}"'
    attributes += "".join(f' {key}="{value}"' for key, value in (("solver", option.solver),
                                                                  ("iterations", option.iterations),
                                                                  ("jacobian", option.jacobian)) if value is not None)
    flags = "" if contacts else '<flag contact="disable"/>'
    # the contact is a spring-damper of natural frequency omega_0 = 1 / (CONTACT_STEPS dt) and
    # damping ratio zeta: in solref's (time constant, damping ratio) form, omega_0 = 1 /
    # (time constant zeta), so the time constant is CONTACT_STEPS dt / zeta
    stiffest = CONTACT_STEPS * dt

    def contact(body: int | None, e: float, mu: float) -> str:
        # a static geom takes no part in averaging the contact parameters (solmix 0): each
        # body-shape contact is the body's; body-body contacts average the two bodies'
        zeta = damping_ratio(e)
        attrs = f' solref="{float(stiffest / zeta)!r} {zeta!r}"'
        attrs += f' friction="{float(mu)!r} 0.005 0.0001"' if mu > 0 else ' condim="1"'
        return attrs + (' solmix="0"' if body is None else "")

    rigid = {shape.body: shape for shape in rigid_shapes(model, bodies, parts.collisions)}
    turn = np.broadcast_to(quat.IDENTITY, (parts.n, 4)).copy()
    spin = np.zeros((parts.n, 3))  # body frame, as MuJoCo's free joint keeps it
    if rigid:
        turn[bodies.index] = bodies.orientations
        spin[bodies.index] = bodies.body_angular_velocities()
    world, moving_bodies = [], []
    for i in range(parts.n):
        e, mu = parts.against_shapes(i)
        collide = contact(i, e, mu) if contacts else ' contype="0" conaffinity="0"'
        if i in rigid:
            shape = rigid[i]
            geom = f'<geom name={quoteattr(f"body{i}")} {_geom(shape)}{collide}/>'
            inertial = (f'<inertial pos="0 0 0" mass="{float(shape.mass)!r}" '
                        f'diaginertia="{_vec(shape.inertia)}"/>')
            orientation = f' quat="{_vec(turn[i])}"'
        else:
            geom = (f'<geom name={quoteattr(f"body{i}")} type="sphere" size="{float(parts.radii[i])!r}" '
                    f'mass="{float(parts.masses[i])!r}"{collide}/>')
            inertial = orientation = ""
        site = f'<site name="s{i}"/>'
        if parts.pinned[i]:
            world.append(f'<site name="s{i}" pos="{_vec(q[i])}"/>'
                         + (geom.replace("<geom ", f'<geom pos="{_vec(q[i])}"{orientation} ') if contacts else ""))
        else:
            moving_bodies.append(f'<body name={quoteattr(parts.names[i])} pos="{_vec(q[i])}"{orientation}>'
                                 f'<freejoint/>{inertial}{geom}{site}</body>')
    for shape in parts.shapes:
        e, mu = parts.collisions.properties(0, shape) if parts.n else (1.0, 0.0)
        where = contact(None, e, mu)
        label = f"name={quoteattr(shape.name)}"
        if isinstance(shape, Plane):
            world.append(f'<geom {label} type="plane" size="0 0 1" pos="{_vec(shape.offset * shape.normal)}" '
                         f'zaxis="{_vec(shape.normal)}"{where}/>')
        elif isinstance(shape, Box):
            world.append(f'<geom {label} type="box" pos="{_vec(shape.center)}" size="{_vec(shape.half_extents)}"'
                         f"{where}/>")
        else:
            axes = _vec(np.concatenate([shape.rotation[:, 0], shape.rotation[:, 1]]))
            world.append(f'<geom {label} type="box" pos="{_vec(shape.center)}" size="{_vec(shape.half_extents)}" '
                         f'xyaxes="{axes}"{where}/>')
    tendons = []
    for i, j, k, rest, c in parts.links:
        if parts.pinned[i] and parts.pinned[j]:
            continue  # neither end moves: no force on anything
        spring = f' stiffness="{float(k)!r}" springlength="{float(rest)!r}"' if rest is not None else ""
        tendons.append(f'<spatial{spring} damping="{float(c)!r}"><site site="s{i}"/><site site="s{j}"/></spatial>')
    moving = ~parts.pinned
    qpos = np.concatenate([np.concatenate([q[i], turn[i]]) for i in np.flatnonzero(moving)]) \
        if moving.any() else np.zeros(0)
    qvel = np.concatenate([np.concatenate([v[i], spin[i]]) for i in np.flatnonzero(moving)]) \
        if moving.any() else np.zeros(0)
    n = int(moving.sum())
    # MuJoCo's arena is allocated once: its broadphase takes 2 bytes per pair of bodies, and
    # the contacts and constraint rows MEGABYTES_PER_1000_BALLS for each thousand balls
    size = f'<size memory="{64 + (2 * n * n) // 2**20 + MEGABYTES_PER_1000_BALLS * n // 1000}M"/>' if n > 200 else ""
    key = f'<keyframe><key name="initial" qpos="{_vec(qpos)}" qvel="{_vec(qvel)}"/></keyframe>' if n else ""
    return "\n".join([
        f"<mujoco model={quoteattr(name)}>",
        "  <!-- written by steplab export: bodies are spheres, springs and dampers are tendons -->" if not rigid else
        "  <!-- written by steplab export: bodies are spheres or their shapes, springs and dampers are tendons -->",
        f"  {size}" if size else "",
        f"  <option {attributes}>{flags}</option>",
        "  <worldbody>", *(f"    {line}" for line in world + moving_bodies), "  </worldbody>",
        *(["  <tendon>", *(f"    {line}" for line in tendons), "  </tendon>"] if tendons else []),
        f"  {key}" if key else "",
        "</mujoco>", ""]).replace("\n\n", "\n")
