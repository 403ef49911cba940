"""Argument types and the argument groups several commands share: time span, contact solver, output."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path

from .errors import EXIT_BAD_INPUT


class Parser(argparse.ArgumentParser):
    """argparse, but errors are one line (usage stays in --help)."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class Deferred(Sequence):
    """Choices computed the first time argparse reads them (to check a value or print help),
    so building the parser imports nothing: the detector names live in the collision package.
    An argument with them needs a ``metavar``, else argparse reads them to build one."""

    def __init__(self, make: Callable[[], Sequence[str]]):
        self._make = make

    @property
    def _items(self) -> tuple[str, ...]:  # read anew each time: a plugin may register a name later
        return tuple(self._make())

    def __getitem__(self, index):
        return self._items[index]

    def __len__(self) -> int:
        return len(self._items)


def _detector_names() -> tuple[str, ...]:
    from steplab.physics.collision.detectors import DETECTOR_NAMES

    return DETECTOR_NAMES


DETECTORS = Deferred(_detector_names)


def _collision_method_names() -> tuple[str, ...]:
    from steplab.physics.collision.methods import COLLISION_METHODS

    return tuple(COLLISION_METHODS)


COLLISION_METHODS = Deferred(_collision_method_names)


def finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text}")
    return value


def positive(text: str) -> float:
    value = finite(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def nonempty(text: str) -> str:
    """A name, a list of names or an address: an empty one is refused, never read as "not given"
    (it was: the default ran instead)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must not be empty")
    return text


def comma_list(text: str) -> list[str]:
    """A comma-separated list of names (``rk4,euler``), each stripped of spaces: an empty list is
    refused as :func:`nonempty` refuses it, and so is an empty item (``rk4,,euler``, a trailing
    comma), never dropped (it was: the other names ran as if it had not been typed)."""
    items = [item.strip() for item in nonempty(text).split(",")]
    empty = [k for k, item in enumerate(items) if not item]
    if empty:
        raise argparse.ArgumentTypeError(f"item {empty[0] + 1} of {len(items)} in {text!r} is empty: give names "
                                         "separated by single commas, none empty (no trailing comma), e.g. rk4,euler")
    return items


def pathname(text: str) -> Path:
    """A file or folder: an empty one is refused (``Path("")`` is the current folder)."""
    return Path(nonempty(text))


#: the most local Dask workers a core: one process each, a few hundred MB each (JAX, Numba, the studies), so
#: more than a few a core only waits and fills memory (99,999 asked for started processes until killed)
MAX_WORKERS_PER_CORE = 4


def worker_count(text: str) -> int:
    """``--workers``: a positive integer, at most MAX_WORKERS_PER_CORE a core of this machine."""
    value, cores = count(text), os.cpu_count() or 1
    if value > MAX_WORKERS_PER_CORE * cores:
        raise argparse.ArgumentTypeError(f"must be at most {MAX_WORKERS_PER_CORE * cores} ({MAX_WORKERS_PER_CORE} "
                                         f"a core, {cores} cores here), got {value}")
    return value


def scene_argument(p) -> None:
    p.add_argument("scene", help="built-in scene name (see `steplab scenes`) or path to a TOML file")


def time_arguments(p, dt: bool = True, steps: bool = False) -> None:
    """--dt, --t-end and (``steps``) --steps, which excludes --t-end."""
    if dt:
        p.add_argument("--dt", type=positive, help="time step, s (default: the scene's)")
    ends = p.add_mutually_exclusive_group() if steps else p
    ends.add_argument("--t-end", type=finite, help="end time, s (default: the scene's)")
    if steps:
        ends.add_argument("--steps", type=count, metavar="N", help="run exactly N steps of dt instead of to --t-end")


def time_span(scene, args) -> tuple[float | None, float]:
    """``(dt, t_end)``: the scene's, with --dt and --t-end applied (dt None where the command has none).

    Raises ValueError, one line, when the run would not reach past the start: t_end not
    later than t_start, or (with a dt and no --steps) a span that holds no whole step,
    with what to pass instead.
    """
    dt = getattr(args, "dt", None)
    dt = scene.dt if dt is None and "dt" in vars(args) else dt
    t_end = getattr(args, "t_end", None)  # a command without --t-end (check): the scene's
    t_end = scene.t_end if t_end is None else t_end
    if not t_end > scene.t_start:
        raise ValueError(f"--t-end {t_end:g} must be later than the scene's t_start = {scene.t_start:g}")
    if dt is not None and getattr(args, "steps", None) is not None:  # refused here, before a warning about the run
        from steplab.integrators.simulate import check_time_advances, steps_end

        check_time_advances(scene.t_start, steps_end(scene.t_start, args.steps, dt), dt,
                            getattr(args, "precision", "float64"))
    if dt is not None and getattr(args, "steps", None) is None:
        from steplab.integrators.simulate import step_count

        try:
            steps = step_count(scene.t_start, t_end, dt)
        except ValueError:  # too many to count: the run itself says so, with what else is wrong
            steps = 1
        if steps < 1:
            ms = f"; a dt in milliseconds? {dt:g} ms is --dt {dt / 1000:g}" if dt >= 1 else ""
            # what this command takes instead (check has neither --t-end nor --steps, animate no --steps)
            instead = [f"--t-end {scene.t_start + dt:g} or later"] if "t_end" in vars(args) else []
            instead += ["--steps N"] if "steps" in vars(args) else []
            instead = ", or ".join(instead) or f"a --dt of at most {t_end - scene.t_start:g} s"
            raise ValueError(f"dt = {dt:g} s is longer than the run, t_end - t_start = {t_end - scene.t_start:g} s: "
                             f"pass {instead}{ms}")
    return dt, t_end


def run_steps(scene, dt: float, t_end: float, max_steps: int | None = None, what: str = "steplab run") -> int:
    """The steps of dt from the scene's t_start to ``t_end``, refused (ValueError, one line) as
    ``simulate`` refuses them before running: a dt that does not advance time, a count too large to
    count; and, given ``max_steps``, more steps than that (``what``: whose limit it is)."""
    from steplab.integrators.simulate import check_time_advances, step_count

    check_time_advances(scene.t_start, t_end, dt, scene.model.dtype)
    steps = step_count(scene.t_start, t_end, dt)
    if max_steps is not None and steps > max_steps:
        raise ValueError(f"{steps} steps of dt = {dt:g} s to t_end = {t_end:g} s exceed {what}'s limit of "
                         f"{max_steps} steps: use a larger --dt or an earlier --t-end")
    return steps


def solver_arguments(p) -> None:
    """Collision handling, --method, and the sweeps of a position-based integrator or of the contact
    solver: --iterations and --substeps (``run.with_sweeps`` says which one takes them)."""
    p.add_argument("--method", choices=COLLISION_METHODS, metavar="NAME",
                   help="collision handling (event: the lecture's event loop, each impact at its time; "
                   "solver: the engines' contact solver; default: the scene's)")
    p.add_argument("--iterations", type=count, metavar="N",
                   help="sweeps per substep of a position-based integrator (pbd, xpbd, vbd: default its "
                   "[simulation.<integrator>] setting, else 10), else of the contact solver (default: the "
                   "scene's, else 1, Box2D v3's)")
    p.add_argument("--substeps", type=count, metavar="N",
                   help="substeps per step of a position-based integrator (default: its setting, else 1), "
                   "else of the contact solver (default: the scene's, else 4)")


def json_argument(p, help: str = "print machine-readable JSON") -> None:
    p.add_argument("--json", action="store_true", help=help)


def study_arguments(p) -> None:
    """Where a study's records go, and where its tasks run."""
    p.add_argument("--quick", action="store_true", help="a short version, for CI (a study in under a minute; "
                   "reproduce about 2 minutes on 2 cores)")
    p.add_argument("--out", type=pathname, default=Path("results"), help="results folder (default: results/)")
    p.add_argument("--force", action="store_true", help="re-run even if the cached result is current")
    where = p.add_mutually_exclusive_group()  # on a Dask cluster (studies/distributed.py); default: this process
    where.add_argument("--workers", type=worker_count, metavar="N", help="run the sweeps' tasks on a local Dask "
                       f"cluster of N worker processes, at most {MAX_WORKERS_PER_CORE} a core (timing studies run "
                       "alone afterwards)")
    where.add_argument("--scheduler", type=nonempty, metavar="ADDRESS", help="run them on the Dask cluster whose "
                       "scheduler is at ADDRESS (e.g. tcp://host:8786; see docs/cluster.md)")


def rotation_argument(p) -> None:
    p.add_argument("--rotation", type=nonempty, metavar="NAME",
                   help="rotation method of the rotating bodies (see `steplab integrators`, kind rotation; default: "
                   "the scene's [simulation] rotation, else exponential-map)")


def rotation_named(scene, args):
    """The run's rotation method: --rotation, else the scene's, else the default; an unknown name
    is one line (UnknownIntegratorError) before anything runs, with or without rotating bodies."""
    from steplab.integrators import DEFAULT_ROTATION, get_rotation

    return get_rotation(args.rotation or scene.rotation or DEFAULT_ROTATION)
