"""``steplab animate``: a simulation as an animation, alone or side by side, for teaching.

Each panel shows the bodies (circles of their true radius) and springs in the plane of the
two axes the motion spans most, and below it the energy against time, so a class sees
both the motion and what the integrator does to the energy.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: at most this many frames are drawn (the trajectory is subsampled to fit)
MAX_FRAMES = 150
AXIS_NAMES = "xyz"


def animate(runs: list[tuple[str, object]], model, out: str | Path, fps: int = 30, view: str | None = None,
            shapes=()) -> Path:
    """Write an animation of one or more runs of the same scene, one panel each.

    Parameters
    ----------
    runs : list of (label, Trajectory)
    model : physics.Model
        The scene's model (body radii, springs, energy).
    out : path ending in .gif (Pillow) or .mp4 (ffmpeg, if installed)
    view : "xy", "xz" or "yz", optional
        The plane shown; by default the two axes the motion spans most.
    shapes : static collision shapes (planes, boxes, oriented boxes) to draw in grey
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import Circle

    from steplab.physics import CentralGravity, Springs
    from steplab.studies.records import write_with

    out = Path(out)
    writers = {".gif": lambda: animation.PillowWriter(fps=fps)}
    if animation.FFMpegWriter.isAvailable():
        writers[".mp4"] = lambda: animation.FFMpegWriter(fps=fps)
    if out.suffix.lower() not in writers:
        raise ValueError(f"--out {out}: unknown animation format {out.suffix or '(none)'!r}; "
                         f"use {' or '.join(writers)}")

    if view is not None:
        axes_idx = [AXIS_NAMES.index(a) for a in view]
    else:
        positions = np.concatenate([traj.positions for _, traj in runs])
        spans = np.ptp(positions[np.isfinite(positions).all(axis=-1)], axis=0)
        axes_idx = sorted(np.argsort(spans)[-2:]) if spans.max() > 0 else [0, 2]
    radii = np.asarray(model.radii, dtype=float)
    springs = [f for f in model.forces if isinstance(f, Springs)]
    # the fixed attracting masses of central gravity, drawn as stars (and kept in the window)
    centers = np.array([np.asarray(f.center, dtype=float) for f in model.forces if isinstance(f, CentralGravity)])
    centers = centers.reshape(-1, 3)
    pairs = np.concatenate([np.stack([np.asarray(f.i), np.asarray(f.j)], 1) for f in springs]) if springs else None

    frames = min(MAX_FRAMES, max(len(traj.t) for _, traj in runs))
    fig, grid = plt.subplots(2, len(runs), figsize=(5.2 * len(runs), 6.4), squeeze=False,
                             gridspec_kw={"height_ratios": [3, 1]})
    artists = []
    for col, (label, traj) in enumerate(runs):
        ax, eax = grid[0][col], grid[1][col]
        lo, hi = _window(np.concatenate([traj.positions[..., axes_idx].reshape(-1, 2), _extent(shapes)[:, axes_idx],
                                         centers[:, axes_idx]]), radii.max())
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_aspect("equal")
        ax.set_xlabel(f"{AXIS_NAMES[axes_idx[0]]} (m)")
        ax.set_ylabel(f"{AXIS_NAMES[axes_idx[1]]} (m)")
        ax.set_title(label, fontsize=10)
        _draw_shapes(ax, shapes, axes_idx, lo, hi)
        if len(centers):
            ax.plot(centers[:, axes_idx[0]], centers[:, axes_idx[1]], "*", color="tab:orange", ms=12,
                    label="attracting mass")
            ax.legend(loc="lower right", fontsize=8)
        lines = LineCollection([], colors="0.5", linewidths=0.8)
        ax.add_collection(lines)
        circles = PatchCollection([Circle((0, 0), r) for r in radii], facecolor="tab:blue", edgecolor="k",
                                  linewidth=0.5)
        ax.add_collection(circles)
        clock = ax.text(0.02, 0.95, "", transform=ax.transAxes, fontsize=9, va="top")
        energy = np.array([float(model.energy(y)) for y in traj.y])
        eax.plot(traj.t, energy, color="0.7", lw=1)
        marker, = eax.plot([], [], "o", color="tab:red", ms=4)
        eax.set_xlabel("time t (s)")
        eax.set_ylabel("energy (J)")
        picks = np.linspace(0, len(traj.t) - 1, frames).round().astype(int)
        artists.append((traj, picks, lines, circles, clock, marker, energy))

    def draw(frame):
        changed = []
        for traj, picks, lines, circles, clock, marker, energy in artists:
            k = picks[frame]
            q = traj.positions[k][:, axes_idx]
            circles.set_paths([Circle(tuple(c), r) for c, r in zip(q, radii)])
            if pairs is not None:
                lines.set_segments(np.stack([q[pairs[:, 0]], q[pairs[:, 1]]], axis=1))
            clock.set_text(f"t = {traj.t[k]:.2f} s")
            marker.set_data([traj.t[k]], [energy[k]])
            changed += [lines, circles, clock, marker]
        return changed

    fig.tight_layout()
    anim = animation.FuncAnimation(fig, draw, frames=frames, interval=1000 / fps, blit=False)
    try:
        # the writers need a real file (Pillow and ffmpeg pick the format from its name):
        # the one atomic writer hands them a temporary one and moves it into place
        write_with(out, lambda tmp: anim.save(tmp, writer=writers[out.suffix.lower()]()))
    finally:
        plt.close(fig)
    return out


def _window(q, pad):
    """Plot limits around the finite positions q (..., 2), square enough to read a 1-D motion.

    Each panel gets its own window, so a run that blows up does not shrink the others.
    """
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


def _draw_shapes(ax, shapes, axes_idx, lo, hi):
    """Static geometry projected on the view plane: boxes as their outline, planes as lines."""
    from matplotlib.patches import Polygon
    from scipy.spatial import ConvexHull

    from steplab.physics.collision import Box, OrientedBox, Plane

    for shape in shapes:
        if isinstance(shape, (Box, OrientedBox)):
            if isinstance(shape, Box):
                corners = np.array([[(shape.lo, shape.hi)[(k >> a) & 1][a] for a in range(3)] for k in range(8)])
            else:
                signs = np.array([[1 if (k >> a) & 1 else -1 for a in range(3)] for k in range(8)])
                corners = shape.center + (signs * shape.half_extents) @ shape.rotation.T
            flat = corners[:, axes_idx]
            try:
                hull = flat[ConvexHull(flat).vertices]
            except Exception:  # a box seen edge-on: draw its extent as a line
                hull = flat[[np.argmin(flat[:, 0] + flat[:, 1]), np.argmax(flat[:, 0] + flat[:, 1])]]
            ax.add_patch(Polygon(hull, closed=True, facecolor="0.75", edgecolor="0.3", zorder=0))
        elif isinstance(shape, Plane):
            n = np.asarray(shape.normal, float)[axes_idx]
            if np.hypot(*n) < 1e-9:
                continue  # the plane is parallel to the view
            # points with n . (a, b) = offset, across the window, and shading on the solid side
            if abs(n[1]) >= abs(n[0]):
                a = np.array([lo[0], hi[0]])
                b = (shape.offset - n[0] * a) / n[1]
            else:
                b = np.array([lo[1], hi[1]])
                a = (shape.offset - n[1] * b) / n[0]
            ax.plot(a, b, color="0.3", lw=2, zorder=0)
