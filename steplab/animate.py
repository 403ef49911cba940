"""``steplab animate``: a simulation as an animation, alone or side by side, for teaching.

Each panel shows the bodies (circles of their true radius, or a visible minimum) and springs
in the plane of the two axes the motion spans most, and below it the energy's change against
time, so a class sees both the motion and what the integrator does to the energy. Side by
side, the panels share their axes: what looks bigger is bigger.

A scene with rotating bodies comes with each run's rotation (``integrators.scene_rotation.
run_rotation``: as the contact solver or the attached step turned them, else free beside the
translation), and each rotating body is drawn as it is at each frame's orientation: a box as its
faces toward the viewer, shaded by a fixed light (:func:`box_faces`), inside the outline of its
turned box on the view plane (:func:`box_outline`), far bodies first; a capsule or cylinder as its
outline; a sphere as its disc with two black spokes from its centre to body-fixed points on its
surface, so that tumbling, spin and rolling show. The energy panel is then the mechanical energy
``steplab run`` reports, the spin 1/2 omega . I omega included (:func:`drawn_energies`).

A scene whose springs act at body-frame points (offsets on rotating bodies, stepped by
:mod:`steplab.integrators.attached`) has its springs drawn to their attachment points x + R(q) r,
each rotating body's lever arms as black lines from its centre to its springs' points on it, and
its energy has the springs at the lever arms of each saved state.

The static parts of the figure (axes, ticks, the energy curves) are drawn once; each frame
redraws only the bodies, springs, clock and energy marker on top of them (blitting), and the
frames go straight to Pillow (GIF) or ffmpeg (MP4).

This module is the driver: the figure, its panels and the frames. What it draws comes from
:mod:`steplab.drawing` (the bodies' shapes, the springs' attachment points, the plane and window) and
:mod:`steplab.drawn_energy` (the energy panels' energy); their names stay importable from here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# what is drawn, from steplab.drawing (the geometry) and steplab.drawn_energy (the energy): the names the driver
# calls are looked up here, so that a spy on steplab.animate.energy_changes or .motion_view sees animate()'s
# calls; the others (``name as name``) stay importable from steplab.animate
from steplab.drawing import CORNERS as CORNERS
from steplab.drawing import FACE_CORNERS as FACE_CORNERS
from steplab.drawing import FACE_NORMALS as FACE_NORMALS
from steplab.drawing import FILL as FILL
from steplab.drawing import MAX_SHARED_ZOOM as MAX_SHARED_ZOOM
from steplab.drawing import OUTSIDE as OUTSIDE
from steplab.drawing import ROUND as ROUND
from steplab.drawing import (
    _extent,
    attached_frames,
    half_extents,
    motion_view,
    rigid_outlines,
    rigid_polygons,
    shared_window,
)
from steplab.drawing import attached_segments as attached_segments
from steplab.drawing import box_faces as box_faces
from steplab.drawing import box_outline as box_outline
from steplab.drawing import convex_hull as convex_hull
from steplab.drawing import toward_viewer as toward_viewer
from steplab.drawn_energy import attached_energies as attached_energies
from steplab.drawn_energy import drawn_energies, energy_changes

if TYPE_CHECKING:  # matplotlib is imported only when an animation is drawn
    from matplotlib.collections import LineCollection, PatchCollection, PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.text import Text

#: at most this many frames are drawn (the trajectory is subsampled to fit)
MAX_FRAMES = 150
AXIS_NAMES = "xyz"
#: a body is drawn at least this fraction of its window across: a 5 cm ball must stay visible
#: in the 100 m frame an unstable run needs
MIN_DRAWN_RADIUS = 0.012
#: m: the widest window drawn; matplotlib's tick locators overflow on a window near the float range (a body of
#: radius 1e308 m, a static box of 1e308 m), so a wider one is refused in one line
MAX_WINDOW = 1e300
#: pixels per inch of the written frames
DPI = 100
#: inches: a scene panel's largest width and height (the other side follows the window's aspect
#: ratio, so an equal-aspect panel fills its figure with no empty band), the energy panel's height
PANEL_WIDTH, PANEL_HEIGHT, ENERGY_HEIGHT = 5.2, 5.0, 1.7
#: at most this many labelled ticks per axis (more crowd into each other on a 5-inch panel)
MAX_TICKS = 5
FORMATS = (".gif", ".mp4")
#: the fastest frame rate: a GIF's frame delay is counted in hundredths of a second, so 100 frames a
#: second is its shortest (a faster rate rounded to a delay of 0, which viewers play at a pace of their own)
MAX_FPS = 100


def check_fps(fps: int) -> None:
    """Raise ``ValueError`` (one line) unless ``fps`` is an integer from 1 to MAX_FPS."""
    if isinstance(fps, bool) or not (isinstance(fps, (int, np.integer)) and 1 <= fps <= MAX_FPS):
        raise ValueError(f"--fps must be an integer from 1 to {MAX_FPS} (a GIF's shortest frame delay is "
                         f"1/100 s), got {fps!r}")


def check_format(out: str | Path) -> None:
    """Raise ``ValueError`` (one line) unless ``out`` names a format that can be written here.

    GIF needs only Pillow (a matplotlib dependency). MP4 needs an ffmpeg binary: the one the
    ``imageio-ffmpeg`` package ships, or one on ``PATH`` (``apt-get install ffmpeg``).
    """
    suffix = Path(out).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"--out {out}: unknown animation format {Path(out).suffix or '(none)'!r}; "
                         f"use {' or '.join(FORMATS)}")
    if suffix == ".mp4":
        _ffmpeg(out)


def _ffmpeg(out):
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        raise ValueError(f"--out {out}: MP4 needs ffmpeg: `pip install imageio-ffmpeg` (or `apt-get install "
                         "ffmpeg`), or write a .gif") from None


def animate(runs: list[tuple[str, object]], model, out: str | Path, fps: int = 30, view: str | None = None,
            shapes=(), rotations=None, half=None) -> Path:
    """Write an animation of one or more runs of the same scene, one panel each.

    Parameters
    ----------
    runs : list of (label, Trajectory)
    model : physics.Model
        The scene's model (body radii, springs, energy).
    out : path ending in .gif (Pillow) or .mp4 (ffmpeg; see :func:`check_format`)
    view : "xy", "xz" or "yz", optional
        The plane shown; by default the two axes the motion spans most (with ``rotations``: see
        :func:`motion_view`).
    shapes : static collision shapes (planes, boxes, oriented boxes) to draw in grey
    rotations : list of integrators.scene_rotation.RotationTrajectory, optional
        For a model with rotating bodies: each run's rotating bodies at its saved times
        (``integrators.scene_rotation.run_rotation``). They are drawn at each frame's orientation
        (:func:`rigid_outlines`) and the energy is :func:`drawn_energies`, the spin included. With
        springs or dampers at body-frame points, the springs are drawn to their attachment points
        and the lever arms as lines (:func:`attached_segments`).
    half : ndarray (N, 3), optional
        The bodies' half extents (a box's half edges, a capsule's (0, 0, l/2)) where the scene has
        them (its contact solver's ``RigidScene.half``); else they follow from the principal
        moments (:func:`half_extents`).
    """
    import matplotlib

    matplotlib.use("Agg")  # drawn off screen, into the frames

    out = Path(out)
    check_format(out)
    check_fps(fps)
    # what every panel shares: the plane, one window, and each body as it is drawn
    shared = _shared_view(runs, model, view, shapes, rotations, half)
    # the energy panels: each run's change, in one unit for all
    energies = [drawn_energies(model, traj, rotation)
                for (_, traj), rotation in zip(runs, rotations or [None] * len(runs))]
    changes, unit = energy_changes(energies)
    # one column for each run: its scene panel over its energy panel
    frames = min(MAX_FRAMES, max(len(traj.t) for _, traj in runs))
    fig, grid = _figure(shared, len(runs))
    panels = [_panel(grid[:, col], shared, col, run, changes[col], unit, frames) for col, run in enumerate(runs)]
    _energy_scale(grid[1][0], changes)
    # the static figure once, then each frame's moving artists over it, written as they come
    _write_frames(fig, panels, shared, frames, out, fps)
    return out


@dataclass(frozen=True)
class _View:
    """What every panel of one animation shares: the plane it shows, its window, and each body as it is
    drawn there; and each run's points that the window was fitted around, which its panel draws."""

    axes: list[int]  # the two world axes shown, across and up (indices into AXIS_NAMES)
    lo: np.ndarray  # the window's lower left and upper right corners (2,), m
    hi: np.ndarray
    radii: np.ndarray  # each body's drawn radius (N,), m: its own, or MIN_DRAWN_RADIUS of the window
    discs: np.ndarray  # the bodies drawn as circles: all but the rotating boxes, capsules, cylinders
    pairs: np.ndarray | None  # each spring's two bodies (P, 2), its line drawn centre to centre
    centers: np.ndarray  # the fixed attracting masses of central gravity (C, 3), drawn as stars
    statics: tuple  # the static collision shapes, drawn in grey
    # with rotations: the rotating bodies (RotationTrajectory.bodies), their half extents (R, 3), the spheres
    # among them (S,) and each sphere's two spokes in its body frame (S, 2, 3)
    rotating: object = None
    extents: np.ndarray | None = None
    spun: np.ndarray | None = None
    spokes: np.ndarray | None = None
    orientations: list | None = None  # each run's rotating bodies' orientations at every saved state (K, R, 4)
    outlines: list | None = None  # each run's rigid_outlines at every saved state (K, R, P, 2)
    # with springs at body-frame points: each run's springs (K, P, 2, 3) and lever arms (K, B, 2, 3)
    attached: list | None = None

    def shown(self, points) -> np.ndarray:
        """World points (..., 3) on the view plane, clipped onto the window's edge."""
        return np.clip(np.nan_to_num(points[..., self.axes], nan=0.0), self.lo, self.hi)


def _shared_view(runs, model, view, shapes, rotations, half) -> _View:
    """The :class:`_View` of ``runs``: the plane (:func:`_view_plane`), the window around every run
    (:func:`_fitted_window`), and the bodies' drawn sizes, which follow from the window."""
    from steplab.physics import CentralGravity, Springs
    from steplab.physics.attachments import attached_forces

    # with springs at body-frame points, each run's springs (end points) and lever arms at every saved state
    attached = None if rotations is None or not attached_forces(model) else [
        attached_frames(model, traj, rotation) for (_, traj), rotation in zip(runs, rotations)]
    axes = _view_plane(view, runs, attached)
    radii = np.asarray(model.radii, dtype=float)
    springs = [f for f in model.forces if isinstance(f, Springs)]
    pairs = np.concatenate([np.stack([np.asarray(f.i), np.asarray(f.j)], 1) for f in springs]) if springs else None
    # the fixed attracting masses of central gravity, drawn as stars (and kept in the window)
    centers = np.array([np.asarray(f.center, dtype=float) for f in model.forces if isinstance(f, CentralGravity)])
    centers = centers.reshape(-1, 3)
    fixed = np.concatenate([_extent(shapes)[:, axes], centers[:, axes]])
    rotating = extents = outlines = None
    if rotations is not None:
        # each run's rotating bodies on the view plane at every saved state: (K, R, P, 2) points whose hull is
        # each one's outline (a sphere's, a circle)
        rotating = rotations[0].bodies
        extents = half_extents(model, rotating, half)
        outlines = [rigid_outlines(rotating.shapes, extents, radii[rotating.index], traj.positions[:, rotating.index],
                                   rotation.orientations, axes) for (_, traj), rotation in zip(runs, rotations)]
    lo, hi = _fitted_window(runs, axes, attached, outlines, fixed, radii.max())
    drawn_radii = np.maximum(radii, MIN_DRAWN_RADIUS * (hi - lo).max())
    discs = np.arange(len(radii))
    spun = spokes = None
    if rotating is not None:
        round_ = np.array([shape == "sphere" for shape in rotating.shapes], dtype=bool)
        discs = np.setdiff1d(discs, rotating.index[~round_])
        spun = np.flatnonzero(round_)
        # their spokes: from the centre to body-fixed points on the (drawn) surface, along the body x and z axes
        spokes = np.eye(3)[[0, 2]] * drawn_radii[rotating.index[spun], None, None]
    orientations = None if rotations is None else [rotation.orientations for rotation in rotations]
    return _View(axes, lo, hi, drawn_radii, discs, pairs, centers, tuple(shapes), rotating, extents, spun, spokes,
                 orientations, outlines, attached)


def _view_plane(view, runs, attached) -> list[int]:
    """The two world axes shown: ``view``'s; else, with springs at body-frame points, the two along which the
    centres and the attachment points move most (:func:`motion_view`); else the two the centres span most."""
    if view is not None:
        return [AXIS_NAMES.index(a) for a in view]
    if attached is not None:
        return motion_view([np.concatenate([traj.positions, springs.reshape(len(traj.t), -1, 3)], axis=1)
                            for (_, traj), (springs, _) in zip(runs, attached)])
    positions = np.concatenate([traj.positions for _, traj in runs])
    spans = np.ptp(positions[np.isfinite(positions).all(axis=-1)], axis=0)
    return sorted(np.argsort(spans)[-2:]) if spans.max() > 0 else [0, 2]


def _fitted_window(runs, axes, attached, outlines, fixed, pad) -> tuple[np.ndarray, np.ndarray]:
    """The window the panels share (:func:`shared_window`, padded by ``pad``) around each run's centres, its
    attachment points and its rotating bodies' ``outlines`` on the plane of ``axes``, and the ``fixed`` points
    (the static boxes' corners, the attracting masses); one wider than MAX_WINDOW is refused in one line."""
    tracks = [traj.positions[..., axes] for _, traj in runs]
    if attached is not None:
        tracks = [np.concatenate([q, springs[..., axes].reshape(len(q), -1, 2)], axis=1)
                  for q, (springs, _) in zip(tracks, attached)]
    if outlines is not None:
        tracks = [np.concatenate([q, points.reshape(len(q), -1, 2)], axis=1) for q, points in zip(tracks, outlines)]
    lo, hi = shared_window(tracks, fixed, pad)
    width = float(np.max(hi - lo))
    if not width <= MAX_WINDOW:
        across = f"would be {width:.3g} m across" if np.isfinite(width) else "would overflow float64"
        raise ValueError(f"the picture's width {across} (the bodies with their radii, the static boxes and the "
                         f"attracting masses): animate draws at most {MAX_WINDOW:g} m")
    return lo, hi


def _figure(shared: _View, columns: int):
    """The figure and its (2, columns) grid of axes: each run's scene panel, sized to the window's aspect ratio
    (:func:`panel_size`), over its energy panel; the panels of a row share their axes."""
    import matplotlib.pyplot as plt

    width, height = panel_size(shared.hi - shared.lo)
    return plt.subplots(2, columns, figsize=((width + 1.1) * columns, height + ENERGY_HEIGHT + 1.3),
                        squeeze=False, dpi=DPI, gridspec_kw={"height_ratios": [height, ENERGY_HEIGHT]},
                        sharex="row", sharey="row")


@dataclass(frozen=True)
class _Rotating:
    """A panel's rotating bodies: their orientations (K, R, 4) and outline points (K, R, P, 2) at each saved
    state, and the artists that draw them at a frame's."""

    orientations: np.ndarray
    points: np.ndarray
    outlines: PolyCollection  # all but the spheres: a box's faces and outline, a capsule's or cylinder's outline
    spokes: LineCollection  # the spheres' spokes


@dataclass(frozen=True)
class _Attached:
    """A panel's springs at body-frame points: their end points (K, P, 2, 3) and the rotating bodies' lever
    arms (K, B, 2, 3) at each saved state (:func:`attached_frames`), and the artists that draw a frame's
    arms and attachment points."""

    springs: np.ndarray
    arms: np.ndarray
    arm_lines: LineCollection
    points: Line2D


@dataclass(frozen=True)
class _Panel:
    """One run's column as each frame redraws it: the run, the saved state each frame shows, and the artists
    that move (``animated=True``, so that the static figure is drawn once without them)."""

    traj: object  # the run's Trajectory
    picks: np.ndarray  # the saved state each frame shows (frames,)
    change: np.ndarray  # the energy change at each saved state (K,)
    springs: LineCollection  # centre to centre, or to the attachment points
    discs: PatchCollection  # the bodies drawn as circles
    rotating: _Rotating | None
    attached: _Attached | None
    clock: Text
    marker: Line2D  # the frame's time on the energy curve

    def animated(self) -> list:
        """The moving artists in the order each frame draws them: the springs under the bodies, the lever arms
        and attachment points over them."""
        rotating = (self.rotating.outlines, self.rotating.spokes) if self.rotating is not None else ()
        attached = (self.attached.arm_lines, self.attached.points) if self.attached is not None else ()
        return [self.springs, self.discs, *rotating, *attached, self.clock, self.marker]


def _panel(column, shared: _View, col: int, run, change, unit: str, frames: int) -> _Panel:
    """Run ``col``'s column of the figure, ``column`` its two axes: the scene panel's static parts
    (:func:`_scene_axes`) and its moving artists, then the energy panel (:func:`_energy_panel`)."""
    from matplotlib.collections import LineCollection, PatchCollection, PolyCollection
    from matplotlib.patches import Circle
    from matplotlib.ticker import MaxNLocator

    (ax, eax), (label, traj) = column, run
    _scene_axes(ax, shared, label)
    # added in the order they are drawn, so that the bodies cover the springs' ends
    springs = ax.add_collection(LineCollection([], colors="0.5", linewidths=0.8, animated=True))
    discs = ax.add_collection(PatchCollection([Circle((0, 0), r) for r in shared.radii[shared.discs]],
                                              facecolor="tab:blue", edgecolor="k", linewidth=0.5, animated=True))
    rotating = attached = None
    if shared.outlines is not None:  # the rotating bodies at each frame's orientation, spokes on the spheres
        rotating = _Rotating(shared.orientations[col], shared.outlines[col],
                             ax.add_collection(PolyCollection([], animated=True)),
                             ax.add_collection(LineCollection([], colors="k", linewidths=1.2, animated=True)))
    if shared.attached is not None:  # over the bodies: each one's orientation, and the points its springs pull at
        arm_lines = ax.add_collection(LineCollection([], colors="k", linewidths=1.5, animated=True))
        points, = ax.plot([], [], "o", color="tab:orange", mec="k", mew=0.5, ms=4, animated=True)
        attached = _Attached(*shared.attached[col], arm_lines, points)
    clock = ax.text(0.02, 0.95, "", transform=ax.transAxes, fontsize=9, va="top", animated=True)
    marker = _energy_panel(eax, traj.t, change, unit)
    for axis in (ax.xaxis, ax.yaxis, eax.xaxis):
        axis.set_major_locator(MaxNLocator(MAX_TICKS))
    picks = np.linspace(0, len(traj.t) - 1, frames).round().astype(int)
    return _Panel(traj, picks, change, springs, discs, rotating, attached, clock, marker)


def _scene_axes(ax, shared: _View, label: str) -> None:
    """A scene panel's static parts: the shared window at equal aspect, its axes named, the run's ``label`` as
    its title, the static shapes in grey and the attracting masses as stars."""
    ax.set_xlim(shared.lo[0], shared.hi[0])
    ax.set_ylim(shared.lo[1], shared.hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel(f"{AXIS_NAMES[shared.axes[0]]} (m)")
    ax.set_ylabel(f"{AXIS_NAMES[shared.axes[1]]} (m)")
    ax.set_title(label, fontsize=10)
    _draw_shapes(ax, shared.statics, shared.axes, shared.lo, shared.hi)
    if len(shared.centers):
        ax.plot(shared.centers[:, shared.axes[0]], shared.centers[:, shared.axes[1]], "*", color="tab:orange",
                ms=12, label="attracting mass")
        ax.legend(loc="lower right", fontsize=8)


def _energy_panel(eax, t, change, unit: str):
    """A run's energy panel: its energy ``change`` against the saved times ``t``, drawn once, about a line at 0;
    returns the marker each frame moves along it."""
    eax.plot(t, change, color="0.6", lw=1)
    eax.axhline(0.0, color="0.85", lw=0.8, zorder=0)
    marker, = eax.plot([], [], "o", color="tab:red", ms=4, animated=True)
    eax.set_xlabel("time t (s)")
    eax.set_ylabel(f"energy change\n({unit})", fontsize=9)
    return marker


def _write_frames(fig, panels: list[_Panel], shared: _View, frames: int, out: Path, fps: int) -> None:
    """Draw the static figure once, then each frame's moving artists over a copy of it (blitting), and write the
    frames to ``out`` as they are drawn; the figure is closed after."""
    import matplotlib.pyplot as plt

    from steplab.core.records import write_with

    fig.tight_layout()
    try:
        fig.canvas.draw()  # everything static, once; the animated artists are left out
        background = fig.canvas.copy_from_bbox(fig.bbox)

        def images():
            for frame in range(frames):
                fig.canvas.restore_region(background)
                for panel in panels:
                    _draw_frame(panel, shared, frame)
                yield np.asarray(fig.canvas.buffer_rgba())[..., :3]

        # Pillow and ffmpeg pick the format from the file's name: the one atomic writer hands
        # them a temporary file with the same suffix and moves it into place
        save = _write_mp4 if out.suffix.lower() == ".mp4" else _write_gif
        write_with(out, lambda tmp: save(tmp, images(), fps))
    finally:
        plt.close(fig)


def _draw_frame(panel: _Panel, shared: _View, frame: int) -> None:
    """Move one panel's artists to the saved state ``frame`` shows, and draw them: a body outside the window
    is drawn on its edge, in red."""
    from matplotlib.patches import Circle

    traj, k, discs = panel.traj, panel.picks[frame], shared.discs
    centres = traj.positions[k][:, shared.axes]
    inside = (np.isfinite(centres).all(axis=1) & (centres >= shared.lo).all(axis=1)
              & (centres <= shared.hi).all(axis=1))
    q = shared.shown(traj.positions[k])  # clipped onto the edge, and marked red
    panel.discs.set_paths([Circle(tuple(c), r) for c, r in zip(q[discs], shared.radii[discs])])
    panel.discs.set_facecolor(np.where(inside[discs], "tab:blue", "tab:red"))
    if panel.rotating is not None:
        _draw_rotating(panel.rotating, shared, k, traj.positions[k], centres, q, inside)
    if panel.attached is not None:  # to the attachment points, not the centres
        _draw_attached(panel.attached, panel.springs, shared, k)
    elif shared.pairs is not None:
        panel.springs.set_segments(np.stack([q[shared.pairs[:, 0]], q[shared.pairs[:, 1]]], axis=1))
    panel.clock.set_text(f"t = {traj.t[k]:.2f} s")
    panel.marker.set_data([traj.t[k]], [panel.change[k]])
    for artist in panel.animated():
        artist.axes.draw_artist(artist)


def _draw_rotating(rotating: _Rotating, shared: _View, k: int, x, centres, q, inside) -> None:
    """The rotating bodies at saved state ``k`` (centres ``x`` (N, 3)): their faces and outlines
    (:func:`rigid_polygons`) and the spheres' spokes, each moved with its centre where that is clipped
    onto the window's edge (from ``centres`` to ``q``, both (N, 2))."""
    from steplab.physics import quaternion as quat

    at, spun = shared.rotating.index, shared.spun
    orientations = rotating.orientations[k]
    shift = (q - np.nan_to_num(centres, nan=0.0))[at]
    verts, faces, edges, widths = rigid_polygons(shared.rotating.shapes, shared.extents, x[at], orientations,
                                                 rotating.points[k], shared.axes, inside[at])
    rotating.outlines.set_verts([v + shift[b] for v, b in verts])
    rotating.outlines.set_facecolor(faces)
    rotating.outlines.set_edgecolor(edges)
    rotating.outlines.set_linewidth(widths)
    turned_spokes = quat.rotate(np, orientations[spun, None], shared.spokes)[..., shared.axes]
    ends = q[at[spun], None] + np.nan_to_num(turned_spokes, nan=0.0)
    rotating.spokes.set_segments([[c, e] for c, pair in zip(q[at[spun]], ends) for e in pair])


def _draw_attached(attached: _Attached, springs, shared: _View, k: int) -> None:
    """The springs at saved state ``k`` to their attachment points, each rotating body's lever arms, and the
    points themselves; ``springs`` is the panel's spring lines."""
    springs.set_segments(shared.shown(attached.springs[k]))
    attached.arm_lines.set_segments(shared.shown(attached.arms[k]))
    ends = shared.shown(attached.springs[k].reshape(-1, 3))
    attached.points.set_data(ends[:, 0], ends[:, 1])


def _write_gif(path: Path, images, fps: int) -> None:
    from PIL import Image

    # each frame is quantised to its own 256-colour palette; the duration is per frame, ms
    frames = [Image.fromarray(np.ascontiguousarray(image)).quantize(256) for image in images]
    frames[0].save(path, save_all=True, append_images=frames[1:], duration=round(1000 / fps), loop=0)


def _write_mp4(path: Path, images, fps: int) -> None:
    import imageio_ffmpeg  # check_format has made sure it finds an ffmpeg

    writer = None
    for image in images:
        # H.264 in yuv420p needs an even width and height: drop an odd last row or column
        image = np.ascontiguousarray(image[: image.shape[0] // 2 * 2, : image.shape[1] // 2 * 2])
        if writer is None:
            writer = imageio_ffmpeg.write_frames(str(path), (image.shape[1], image.shape[0]), fps=fps,
                                                 macro_block_size=1, ffmpeg_log_level="error")
            writer.send(None)  # start ffmpeg
        writer.send(image)
    writer.close()


def _energy_scale(eax, changes) -> None:
    """The energy panels share their y axis; symmetric-log when the runs differ by orders of magnitude,
    so a 1 % wobble and a 10^4 % blow-up are both readable (and both honest)."""
    sizes = [np.nanmax(np.abs(np.where(np.isfinite(c), c, np.nan))) for c in changes]
    sizes = [s for s in sizes if np.isfinite(s) and s > 0]
    if len(sizes) > 1 and max(sizes) > 30 * min(sizes):
        # the linear part, |change| < the smallest run's, gets as much height as three decades
        eax.set_yscale("symlog", linthresh=min(sizes), linscale=3)
        # a labelled tick every few decades, not every one (16 decades crowd into an inch)
        decades = np.arange(np.ceil(np.log10(min(sizes))), np.floor(np.log10(max(sizes))) + 1)
        decades = decades[::max(1, int(np.ceil(len(decades) / (MAX_TICKS - 1))))]
        lows = [-10.0**d for d in decades[::-1]] if min(np.nanmin(c) for c in changes) < 0 else []
        eax.set_yticks(lows + [0.0] + [10.0**d for d in decades])


def panel_size(span) -> tuple[float, float]:
    """Width and height (inches) of a scene panel that shows ``span`` (metres, 2) at equal aspect."""
    aspect = float(span[1] / span[0]) if span[0] > 0 else 1.0
    width = min(PANEL_WIDTH, PANEL_HEIGHT / aspect)
    return width, max(1.5, width * aspect)


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
