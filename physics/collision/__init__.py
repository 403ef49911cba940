"""Collisions: shapes, narrow phase, bounding volumes, time of impact, detectors, response, events.

>>> from steplab.physics.collision import Sphere, Plane, collide
>>> import numpy as np
>>> contact = collide(Sphere(np.array([0.0, 0.0, 0.05]), np.array(0.1)), Plane(np.array([0.0, 0.0, 1.0])))
>>> float(contact.penetration_depth)
0.05

One module per concept (the lecture's collision chapters):

- :mod:`.shapes` — spheres (the bodies), planes, axis-aligned and oriented boxes;
- :mod:`.narrow_phase` — one pair test per pair of kinds, in a table (:data:`PAIR_TESTS`);
- :mod:`.manifolds` — the rigid narrow phase: contact manifolds of spheres, boxes and capsules
  (the module keeps its name here: call ``manifolds.manifolds``);
- :mod:`.bounding_volumes` — sphere, AABB, OBB and a two-level hierarchy;
- :mod:`.time_of_impact` — swept tests: sphere-sphere (the lecture's quadratic), sphere-plane,
  sphere-box through the Minkowski sum;
- :mod:`.overlap`, :mod:`.swept`, :mod:`.detectors` — overlap testing with bisection,
  intersection testing;
- :mod:`.response` — the impulse with restitution (equation 4), friction, materials;
- :mod:`.resting` — resting contact;
- :mod:`.events` — prologue, epilogue, the collision log;
- :mod:`.step` — the physics step, stage by stage, and its two event loops; :mod:`.impact_queue`,
  :mod:`.changed_pairs`, :mod:`.coupling` — what the incremental loop keeps and re-tests;
  :mod:`.impact_cap` — the bound on impacts per step; :mod:`.world` — one scene's setup.
"""

from __future__ import annotations

from .bounding_volumes import AABB as AABB
from .bounding_volumes import OBB as OBB
from .bounding_volumes import BoundingSphere as BoundingSphere
from .bounding_volumes import Hierarchy as Hierarchy
from .bounding_volumes import hierarchy_overlaps as hierarchy_overlaps
from .bounding_volumes import overlaps as overlaps
from .contact import Contact as Contact
from .detectors import DETECTOR_NAMES as DETECTOR_NAMES
from .events import Collision as Collision
from .events import CollisionLog as CollisionLog
from .events import cancel_triggers as cancel_triggers
from .events import remove_on_impact as remove_on_impact
from .impact_cap import ImpactCapError as ImpactCapError
from .manifolds import ManifoldPoints as ManifoldPoints
from .manifolds import Poses as Poses
from .manifolds import RigidShapes as RigidShapes
from .manifolds import bounding_radius as bounding_radius
from .narrow_phase import PAIR_TESTS as PAIR_TESTS
from .narrow_phase import collide as collide
from .response import PairProperties as PairProperties
from .response import impulse as impulse
from .shapes import Box as Box
from .shapes import OrientedBox as OrientedBox
from .shapes import Plane as Plane
from .shapes import Sphere as Sphere
from .shapes import rotation_matrix as rotation_matrix
from .time_of_impact import time_of_impact as time_of_impact
from .world import EVENT_LOOPS as EVENT_LOOPS
from .world import CollisionWorld as CollisionWorld
