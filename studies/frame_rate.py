"""Frame-rate independence study: the fixed-step accumulator loop against a naive variable step.

The same scene (the oscillator, semi-implicit Euler) is played through several
frame-time sequences: steady 30, 60 and 144 Hz, a jittery 60 Hz, and 60 Hz with one
long stall. The fixed-step loop (:class:`integrators.GameLoop`) runs the physics in
steps of ``dt`` whatever the frames; the naive loop takes one step of the frame's
length per frame. Recorded: how far each loop's final state drifts between frame
sequences (the fixed step: not one bit), its error against the exact solution, and
what render interpolation does to what a player sees.
"""

from __future__ import annotations

import hashlib

import numpy as np
from steplab.integrators import GameLoop, get_integrator
from steplab.integrators.game_loop import interpolate

from . import plotting
from .problems import oscillator_problem
from .runner import Study, run_tasks
from .tables import Table, markdown_table

INTEGRATOR = "semi-implicit-euler"
PHYSICS_DT = 1 / 120


def frame_sequences(duration: float, seed: int) -> dict[str, list[float]]:
    """Frame times (s) that each add up to ``duration`` (seeded jitter)."""
    rng = np.random.default_rng(seed)

    def steady(hz):
        return [1 / hz] * int(round(duration * hz))

    jitter = list(1 / 60 * rng.uniform(0.5, 1.5, size=int(duration * 60 * 1.2)))
    stall = steady(60)
    stall[len(stall) // 2] = 0.25  # one quarter-second hitch
    sequences = {"steady 30 Hz": steady(30), "steady 60 Hz": steady(60), "steady 144 Hz": steady(144),
                 "jittery 60 Hz": jitter, "60 Hz with a 0.25 s stall": stall}
    return {name: _trim(frames, duration) for name, frames in sequences.items()}


def _trim(frames: list[float], duration: float) -> list[float]:
    """Cut or extend a sequence so that its frames add up to ``duration`` (to float precision)."""
    out, total = [], 0.0
    for f in frames:
        if total + f >= duration:
            break
        out.append(f)
        total += f
    out.append(duration - total)
    return out


def parameters(quick: bool) -> dict:
    # the end time sits half a step past a step boundary, so rounding in the frame sums
    # can never change how many fixed steps are due
    steps = 120 if quick else 1200
    return {"integrator": INTEGRATOR, "physics_dt": PHYSICS_DT, "duration": (steps + 0.5) * PHYSICS_DT,
            "seed": 2026}


def _digest(y) -> str:
    return hashlib.sha256(np.ascontiguousarray(y).tobytes()).hexdigest()[:16]


def tasks(params: dict) -> list[list]:
    """One task per frame sequence, and one for the interpolation trace."""
    return [["sequence", name] for name in frame_sequences(params["duration"], params["seed"])] + [["interpolation"]]


def task(params: dict, item: list) -> dict:
    """Play one frame sequence through both loops (or trace the interpolation)."""
    problem = oscillator_problem(0.0)
    model, integrator = problem.model, get_integrator(params["integrator"])
    dt = params["physics_dt"]
    if item[0] == "interpolation":
        return _interpolation_trace(problem, integrator, dt)
    name = item[1]
    frames = frame_sequences(params["duration"], params["seed"])[name]
    physics = _Physics(model, integrator, problem.y0, dt)
    loop = GameLoop(physics.step, dt)
    for frame in frames:
        loop.advance(frame)
    fixed = physics.y
    # naive: one step of the frame's length per frame
    y, t = problem.y0.copy(), 0.0
    for frame in frames:
        y, _ = integrator.step(model, t, y, frame, integrator.init(model, t, y))
        t += frame
    return {
        "sequence": name, "frames": len(frames), "longest_frame": max(frames),
        "fixed_steps": loop.steps, "fixed_final_x": float(fixed[0, 1, 0]), "fixed_digest": _digest(fixed),
        "fixed_error": float(abs(fixed[0, 1, 0] - problem.solution(loop.steps * dt)[0, 1, 0])),
        "naive_final_x": float(y[0, 1, 0]),
        "naive_error": float(abs(y[0, 1, 0] - problem.solution(params["duration"])[0, 1, 0])),
    }


def reduce(params: dict, results: list) -> dict:
    """The record: every sequence's run, how far the final states spread, and the trace."""
    *runs, interpolation = results
    spread = {
        "fixed": float(np.ptp([r["fixed_final_x"] for r in runs])),
        "naive": float(np.ptp([r["naive_final_x"] for r in runs])),
    }
    identical = len({r["fixed_digest"] for r in runs}) == 1
    return {"runs": runs, "final_state_spread": spread, "fixed_bit_identical": identical,
            "interpolation": interpolation}


def compute(params: dict, progress=None) -> dict:
    """Every task in turn, then the reduction (a run without a cluster)."""
    return run_tasks(STUDY, params, progress)


class _Physics:
    """The physics state a game loop advances: the latest and the previous state."""

    def __init__(self, model, integrator, y0, dt):
        self.model, self.integrator, self.dt = model, integrator, dt
        self.y = self.previous = y0.copy()
        self.t, self.carry = 0.0, integrator.init(model, 0.0, y0)

    def step(self):
        self.previous = self.y
        self.y, self.carry = self.integrator.step(self.model, self.t, self.y, self.dt, self.carry)
        self.t += self.dt


def _interpolation_trace(problem, integrator, dt: float, display_hz: float = 144.0, duration: float = 0.5):
    """What a 144 Hz display shows of 60 Hz physics: latest state, interpolated state, truth."""
    physics_dt = 1 / 60
    state = _Physics(problem.model, integrator, problem.y0, physics_dt)
    loop = GameLoop(state.step, physics_dt)
    trace = {"t": [], "latest": [], "interpolated": [], "exact": []}
    frame, clock = 1 / display_hz, 0.0
    while clock < duration:
        alpha = loop.advance(frame)
        clock += frame
        trace["t"].append(clock)
        trace["latest"].append(float(state.y[0, 1, 0]))
        trace["interpolated"].append(float(interpolate(state.previous, state.y, alpha)[0, 1, 0]))
        trace["exact"].append(float(problem.solution(clock)[0, 1, 0]))
    trace["physics_dt"], trace["display_hz"] = physics_dt, display_hz
    return trace


def plot(record: dict, out) -> list[str]:
    plt = plotting.plt
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 4.8))
    runs = record["runs"]
    names = [r["sequence"] for r in runs]
    x = np.arange(len(runs))
    ax1.bar(x - 0.2, [max(r["fixed_error"], 1e-17) for r in runs], 0.4, label="fixed step (accumulator)")
    ax1.bar(x + 0.2, [max(r["naive_error"], 1e-17) for r in runs], 0.4, label="naive: one step per frame")
    ax1.set_yscale("log")
    ax1.set_xticks(x, names, rotation=20, ha="right", fontsize=8)
    ax1.set_ylabel("final position error against the exact solution (m)")
    bits = "bit-identical" if record["fixed_bit_identical"] else "NOT identical"
    ax1.set_title(f"Same scene, different frame rates\nfixed-step final states: {bits} across sequences; "
                  f"naive spread {record['final_state_spread']['naive']:.2g} m", fontsize=10)
    ax1.legend(fontsize=8)
    tr = record["interpolation"]
    ax2.plot(tr["t"], tr["exact"], "k-", lw=1, label="exact")
    ax2.step(tr["t"], tr["latest"], where="post", color="tab:red", lw=1.2,
             label="latest physics state (judder)")
    ax2.plot(tr["t"], tr["interpolated"], color="tab:green", lw=1.2,
             label="interpolated with alpha (smooth, one step behind)")
    ax2.set_xlabel("time t (s)")
    ax2.set_ylabel("rendered position x (m)")
    ax2.set_title(f"What a {tr['display_hz']:g} Hz display shows of {1 / tr['physics_dt']:g} Hz physics",
                  fontsize=10)
    ax2.legend(fontsize=8)
    fig.tight_layout()
    return plotting.save_figure(fig, out, "frame_rate")


def summary(record: dict) -> list[tuple[str, str]]:
    rows = [("fixed-step final states bit-identical", str(record["fixed_bit_identical"])),
            ("naive final-position spread", f"{record['final_state_spread']['naive']:.3g} m")]
    for r in record["runs"]:
        rows.append((f"error, {r['sequence']}", f"fixed {r['fixed_error']:.2g} m, naive {r['naive_error']:.2g} m"))
    return rows


# --- the paper's tables -------------------------------------------------------------


def frame_rate_table(data: list[dict]) -> str:
    """Each frame sequence's longest frame and the final error of the fixed and the naive step."""
    rows = [[r["sequence"], str(r["frames"]), f"{r['longest_frame'] * 1e3:.1f}", f"{r['fixed_error']:.2g}",
             f"{r['naive_error']:.2g}"] for r in data]
    return markdown_table(["frame sequence", "frames", "longest frame (ms)", "fixed-step error (m)",
                           "naive error (m)"], rows)


TABLES = (Table("frame_rate", lambda r: r["runs"], frame_rate_table),)


STUDY = Study("frame_rate", "Frame-rate independence: fixed-step accumulator against a naive variable step",
              parameters, compute, plot, summary, tables=TABLES,
              tasks=tasks, task=task, reduce=reduce)
