"""The geometry of what ``steplab animate`` draws, apart from any figure: each rotating body's shape on the
view plane (its half extents, outline points, a box's faces toward the viewer and their shading, a convex hull),
the springs to their body-frame attachment points and the lever arms, and the plane and window the panels share.

Pure NumPy (SciPy and steplab.physics inside the functions that use them); :mod:`steplab.animate` draws what
these return.
"""

from __future__ import annotations

import numpy as np

#: the corners of the box [-1, 1]^3, (8, 3), in the order of the bits (x, y, z) of their index
CORNERS = np.array([[1.0 if (k >> a) & 1 else -1.0 for a in range(3)] for k in range(8)])
#: points on a circle that a capsule's or cylinder's outline is drawn through
ROUND = 24


def half_extents(model, bodies, half=None) -> np.ndarray:
    """Each rotating body's half extents (R, 3), m: a box's half edges, a capsule's or cylinder's
    (0, 0, l / 2), a sphere's zeros.

    ``half`` (N, 3), where the scene has them (its contact solver's ``RigidScene.half``), gives
    them; else they follow from the principal moments and the mass, which a scene without
    collisions keeps: the box of edges a^2 = 6 (I2 + I3 - I1) / m (and so on), the cylinder of
    length l^2 = 12 I1 / m - 3 r^2, the capsule whose I1 the moments give (the shape's own size
    when its moments came from it; for moments given in the file, the solid of the shape that has
    them).
    """
    if half is not None:
        return np.asarray(half, float)[bodies.index]
    bodies_half = np.zeros((len(bodies.index), 3))
    inertia = np.asarray(bodies.inertia, float)
    masses = np.asarray(model.masses, float)[bodies.index]
    radii = np.asarray(model.radii, float)[bodies.index]
    for b, shape in enumerate(bodies.shapes):
        moments, m, r = inertia[b], masses[b], radii[b]
        if shape == "box":
            bodies_half[b] = np.sqrt(np.maximum(1.5 * (moments.sum() - 2 * moments) / m, 0.0))
        elif shape == "cylinder":
            bodies_half[b, 2] = 0.5 * np.sqrt(max(12 * moments[0] / m - 3 * r * r, 0.0))
        elif shape == "capsule":
            bodies_half[b, 2] = 0.5 * _capsule_length(moments[0], m, r)
    return bodies_half


def _capsule_length(across: float, mass: float, radius: float) -> float:
    """The length of the capsule's cylindrical part whose moment about a transverse axis is ``across``
    (``physics.rigid_body.principal_inertia``, which grows with the length), 0 for a sphere's or less."""
    from scipy.optimize import brentq

    from steplab.physics.rigid_body import principal_inertia

    def excess(length):
        return principal_inertia("capsule", mass, radius, length=length)[0] - across

    if excess(0.0) >= 0:
        return 0.0
    top = radius
    while excess(top) < 0 and top < 1e12 * radius:
        top *= 2
    return float(brentq(excess, 0.0, top, xtol=1e-12 * top))


def box_outline(center, orientation, half, axes=(0, 1)) -> np.ndarray:
    """The outline (M, 2) of a box on a view plane, counter-clockwise: the convex hull of its eight
    corners ``center + R(orientation) (+-half)`` projected on the plane of ``axes`` (indices of two
    world axes, such as (0, 2) for x-z). A box seen face on is its rectangle (M = 4), one turned
    in 3-D a hexagon (M = 6)."""
    from steplab.physics import quaternion as quat

    turned = quat.rotate(np, np.asarray(orientation, float), CORNERS * np.asarray(half, float))
    corners = np.asarray(center, float) + turned
    return convex_hull(corners[:, list(axes)])


def rigid_outlines(shapes, half, radii, centers, orientations, axes) -> np.ndarray:
    """Points (..., R, P, 2) on the view plane ``axes`` whose convex hull is each rotating body's outline
    at ``centers`` (..., R, 3) and ``orientations`` (..., R, 4): a box's eight corners, a cylinder's two
    rims, the circles of a capsule's two caps and of a sphere (ROUND points each); a body's row repeats
    its points up to the largest count P of the bodies."""
    from steplab.physics import quaternion as quat

    centers, orientations = np.asarray(centers, float), np.asarray(orientations, float)
    half, radii = np.asarray(half, float), np.asarray(radii, float)
    axes = list(axes)
    count = 8 if all(shape == "box" for shape in shapes) else 2 * ROUND
    out = np.zeros((*centers.shape[:-1], count, 2))
    angle = 2 * np.pi * np.arange(ROUND) / ROUND
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=-1)  # (ROUND, 2), on the view plane
    for b, shape in enumerate(shapes):
        x, q = centers[..., b, None, :], orientations[..., b, None, :]
        if shape == "box":
            points = (x + quat.rotate(np, q, CORNERS * half[b]))[..., axes]
        elif shape == "cylinder":
            rim = np.concatenate([np.stack([radii[b] * circle[:, 0], radii[b] * circle[:, 1],
                                            np.full(ROUND, z)], axis=-1) for z in (-half[b, 2], half[b, 2])])
            points = (x + quat.rotate(np, q, rim))[..., axes]
        else:  # a sphere (the cap ends at its centre) or a capsule: circles about the ends of its segment
            ends = (x + quat.rotate(np, q, np.array([[0.0, 0.0, -half[b, 2]], [0.0, 0.0, half[b, 2]]])))[..., axes]
            points = (ends[..., :, None, :] + radii[b] * circle).reshape(*ends.shape[:-2], 2 * ROUND, 2)
        out[..., b, :, :] = points[..., np.arange(count) % points.shape[-2], :]
    return out


#: the faces of the box [-1, 1]^3: each one's outward normal (6, 3) and its corners (6, 4), indices into CORNERS
#: in order around it
FACE_NORMALS = np.concatenate([np.eye(3), -np.eye(3)])
FACE_CORNERS = np.array([[next(c for c in range(8) if CORNERS[c, i] == sign and CORNERS[c, (i + 1) % 3] == u
                               and CORNERS[c, (i + 2) % 3] == w) for u, w in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
                         for sign in (1.0, -1.0) for i in range(3)])
#: the fill of a rotating body, and of one outside the window (drawn on its edge), RGB
FILL, OUTSIDE = np.array([0.122, 0.467, 0.706]), np.array([0.839, 0.153, 0.157])


def toward_viewer(axes) -> np.ndarray:
    """The world unit vector out of the screen for the view plane of ``axes`` (the first axis to the
    right, the second up): their cross product, so that x-z is seen from -y."""
    right, up = np.eye(3)[list(axes)]
    return np.cross(right, up)


def box_faces(centers, orientations, half, axes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The faces of boxes at ``centers`` (B, 3) turned by ``orientations`` (B, 4), half edges ``half``
    (B, 3), on the view plane of ``axes``: their corners (B, 6, 4, 2), whether each faces the viewer
    (B, 6) (:func:`toward_viewer`; a face seen edge-on does not) and its brightness (B, 6), the cosine
    of its normal with a light from the viewer's upper left (Lambert's law)."""
    from steplab.physics import quaternion as quat

    centers, orientations = np.asarray(centers, float), np.asarray(orientations, float)
    axes = list(axes)
    corners = centers[:, None] + quat.rotate(np, orientations[:, None], CORNERS * np.asarray(half, float)[:, None])
    normals = quat.rotate(np, orientations[:, None], FACE_NORMALS)
    right, up = np.eye(3)[axes]
    out = toward_viewer(axes)
    light = (2 * out + up - right) / np.sqrt(6.0)
    return corners[:, FACE_CORNERS][..., axes], normals @ out > 1e-9, normals @ light


def rigid_polygons(shapes, half, centers, orientations, points, axes, inside):
    """What one frame draws of the R rotating bodies that are not spheres, far to near (along
    :func:`toward_viewer`), as the polygons of one PolyCollection: ``(verts, faces, edges, widths)``.

    ``verts`` lists ``(polygon (M, 2), body)`` (``body`` its row among the R); a box is its faces
    toward the viewer, each shaded by its brightness (:func:`box_faces`) with a thin edge, then its
    outline (:func:`convex_hull` of its corners) with a black one; a capsule or cylinder is its
    outline, filled. ``points`` (R, P, 2) are :func:`rigid_outlines` at this frame; ``inside`` (R,)
    whether each body is in the window: one outside it is drawn red.
    """
    centers = np.nan_to_num(np.asarray(centers, float), nan=0.0)
    orientations, points = np.nan_to_num(orientations, nan=0.0), np.nan_to_num(points, nan=0.0)
    boxes = np.flatnonzero([shape == "box" for shape in shapes])
    corners, facing, brightness = box_faces(centers[boxes], orientations[boxes], np.asarray(half)[boxes], axes)
    row = {b: n for n, b in enumerate(boxes)}
    verts, faces, edges, widths = [], [], [], []
    for b in np.argsort(centers @ toward_viewer(axes), kind="stable"):
        if shapes[b] == "sphere":
            continue
        fill = FILL if inside[b] else OUTSIDE
        if b in row:
            for f in np.flatnonzero(facing[row[b]]):
                verts.append((corners[row[b], f], b))
                faces.append((*np.clip(fill * (0.55 + 0.6 * brightness[row[b], f]), 0, 1), 1.0))
                edges.append((0.1, 0.1, 0.1, 1.0))
                widths.append(0.4)
        verts.append((convex_hull(points[b]), b))
        faces.append((*fill, 0.0 if b in row else 1.0))
        edges.append((0.0, 0.0, 0.0, 1.0))
        widths.append(0.9)
    return verts, faces, edges, widths


def convex_hull(points) -> np.ndarray:
    """The convex hull (M, 2) of 2-D ``points``, counter-clockwise (SciPy's Qhull); a set without
    area (a body of no extent, or seen edge-on) is drawn as its points."""
    from scipy.spatial import ConvexHull, QhullError

    points = np.asarray(points, float)
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return points


def attached_segments(model, x, orientations, rotating, reach) -> tuple[np.ndarray, np.ndarray]:
    """What one frame of a model with springs at body-frame points draws, world frame, m.

    Parameters
    ----------
    x : ndarray (N, 3)
        The centres.
    orientations : ndarray (N, 4)
        Every body's orientation, the identity for a body that does not rotate.
    rotating : int array
        Which bodies rotate.
    reach : ndarray (N,)
        The length of the orientation line of a rotating body that no spring pulls off its centre.

    Returns
    -------
    springs : ndarray (P, 2, 3)
        Each spring from the point it pulls on its first body, x_i + R(q_i) r_i, to the one on its
        second (the centre for an end without an offset).
    pointers : ndarray (B, 2, 3)
        Each rotating body's orientation: a line from its centre to each point a spring pulls it
        at off its centre, the lever arm R(q) r; along its body-frame x axis, ``reach`` long, for
        a rotating body with no such point.
    """
    from steplab.physics import Springs
    from steplab.physics import quaternion as quat

    x, orientations = np.asarray(x, float), np.asarray(orientations, float)
    springs, pointers, pointed = [np.zeros((0, 2, 3))], [np.zeros((0, 2, 3))], set()
    for f in model.forces:
        if not isinstance(f, Springs):
            continue
        i, j = np.atleast_1d(f.i), np.atleast_1d(f.j)
        ends = np.stack([x[i], x[j]], axis=1)
        if getattr(f, "attachment", None) is not None:
            offsets = np.asarray(f.attachment.offsets, float)
            ends = ends + np.stack([quat.rotate(np, orientations[i], offsets[:, 0]),
                                    quat.rotate(np, orientations[j], offsets[:, 1])], axis=1)
            for end, bodies in enumerate((i, j)):
                off = np.any(offsets[:, end] != 0, axis=-1)
                pointers.append(np.stack([x[bodies[off]], ends[off, end]], axis=1))
                pointed.update(bodies[off].tolist())
        springs.append(ends)
    free = np.array([b for b in np.atleast_1d(rotating).tolist() if b not in pointed], dtype=int)
    axis = quat.rotate(np, orientations[free], np.array([1.0, 0.0, 0.0])) * np.asarray(reach, float)[free, None]
    pointers.append(np.stack([x[free], x[free] + axis], axis=1))
    return np.concatenate(springs), np.concatenate(pointers)


def attached_frames(model, traj, rotation) -> tuple[np.ndarray, np.ndarray]:
    """:func:`attached_segments` at each saved state of ``traj``: springs (K, P, 2, 3), pointers (K, B, 2, 3);
    the orientation line of a body without an attachment point is its radius long."""
    from steplab.integrators.scene_rotation import rotation_arrays

    orientations = rotation_arrays(rotation, model.n_bodies)["orientations"]
    frames = [attached_segments(model, x, o, rotation.bodies.index, model.radii)
              for x, o in zip(traj.positions, orientations)]
    return np.stack([s for s, _ in frames]), np.stack([p for _, p in frames])


#: the panels share one window unless it would be more than this many times wider than a
#: panel's own (a run that diverged to 1e30 m): then the window is capped, and a body outside
#: it is drawn on the edge, in red
MAX_SHARED_ZOOM = 1000.0


def motion_view(tracks: list[np.ndarray]) -> list[int]:
    """The two axes (indices, ascending) along which the points of ``tracks`` move most: each run's
    (K, M, 3), M points (centres, attachment points) at its K saved times.

    Each point's own range over time counts, not how far apart the points are: a pinned anchor, or
    a second pendulum beside the first, does not move, so it does not pick the plane. The extent of
    all the points only breaks ties, such as two axes no point moves along; a move below 1e-6 of the
    largest range is rounding, not motion.
    """
    q = np.concatenate([np.asarray(t, float).reshape(len(t), -1, 3) for t in tracks])
    q = np.where(np.isfinite(q), q, np.nan)
    motion = np.nan_to_num(np.max(np.fmax.reduce(q, axis=0) - np.fmin.reduce(q, axis=0), axis=0, initial=0.0))
    finite = q.reshape(-1, 3)
    finite = finite[np.isfinite(finite).all(axis=1)]
    extent = np.ptp(finite, axis=0) if len(finite) else np.zeros(3)
    largest = max(motion.max(), extent.max())
    if not largest > 0:
        return [0, 2]
    moving = np.where(motion > 1e-6 * largest, motion, 0.0)
    return sorted(np.lexsort((extent, moving))[-2:].tolist())


def shared_window(runs: list[np.ndarray], fixed: np.ndarray, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """One plot window, (lo, hi) of shape (2,), around every run's finite positions (..., 2).

    Square enough to read a 1-D motion, and padded by the largest radius. A run whose own
    window is more than ``MAX_SHARED_ZOOM`` times wider than the narrowest run's does not widen
    it further: the window is capped there (about the narrowest run's centre).
    """
    own = [_window(np.concatenate([q.reshape(-1, 2), fixed]), pad) for q in runs]
    lo = np.min([w[0] for w in own], axis=0)
    hi = np.max([w[1] for w in own], axis=0)
    narrowest = min(own, key=lambda w: (w[1] - w[0]).max())
    cap = MAX_SHARED_ZOOM * (narrowest[1] - narrowest[0]).max() / 2
    centre = (narrowest[0] + narrowest[1]) / 2
    return np.maximum(lo, centre - cap), np.minimum(hi, centre + cap)


def _window(q, pad):
    """Plot limits around the finite positions q (..., 2), square enough to read a 1-D motion."""
    q = q.reshape(-1, 2)
    q = q[np.isfinite(q).all(axis=1)]
    lo, hi = q.min(axis=0), q.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo) / 2
    half = np.maximum(half, 0.5 * half.max()) + pad + 0.05 * half.max()
    return centre - half, centre + half


def _extent(shapes) -> np.ndarray:
    """Corners (k, 3) of the static boxes, so that a panel's window shows them."""
    from steplab.physics.collision import Box, OrientedBox

    points = [np.zeros((0, 3))]
    for shape in shapes:
        if isinstance(shape, Box):
            points.append(np.stack([shape.lo, shape.hi]))
        elif isinstance(shape, OrientedBox):
            reach = np.abs(shape.rotation) @ shape.half_extents
            points.append(np.stack([shape.center - reach, shape.center + reach]))
    return np.concatenate(points)
