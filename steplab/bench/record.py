"""The record of one bench run: every comparison's ratio, medians, minimums and what was compared."""

from __future__ import annotations

import dataclasses

import numpy as np

from steplab.core.timing import Times

from .config import ONE_THREAD, PEER_TARGETS, STABILITY, TARGETS, Config


def final_difference(a, b) -> float:
    """Largest |difference| of two final states (positions and velocities), or of two arrays."""
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)), initial=0.0))


def size_label(n: int) -> str:
    """A size in a comparison's name: ``1e5`` for a power of ten, else the number (``2000``)."""
    e = int(round(np.log10(n)))
    return f"1e{e}" if 10**e == n else str(n)


def clock(steplab: Times, peer: Times) -> str:
    """The clock a ratio is taken on: "cpu" where both sides carry CPU seconds and ran on one
    thread (CPU over wall seconds at most ONE_THREAD in every round, ``Times.threads``), else "wall".

    On one thread, a call's CPU seconds are its wall seconds less the time the scheduler gave
    to other processes: what the wall time would be on an idle core. A side on more threads
    spends more CPU seconds than wall seconds, and its CPU time is not its speed.
    """
    if any(t.cpu is None or t.threads is None or t.threads > ONE_THREAD for t in (steplab, peer)):
        return "wall"
    return "cpu"


def beside(steplab: Times, bound: Times) -> dict:
    """The step against a bound its ratio and target are not on (the same bound warm, or a tighter one), on
    :func:`clock`'s clock: both medians and minimums, and their ratios (steplab / bound)."""
    chosen = clock(steplab, bound)
    ours, theirs = (t.cpu if chosen == "cpu" else t for t in (steplab, bound))
    return {"steplab": ours.median, "bound": theirs.median, "steplab_min": ours.minimum, "bound_min": theirs.minimum,
            "ratio": ours.median / theirs.median, "ratio_of_minimums": ours.minimum / theirs.minimum, "clock": chosen}


def _spread(t: Times) -> dict:
    return {"min": t.minimum, "median": t.median, "max": t.maximum, "rounds": t.rounds}


def _counts(t: Times) -> dict:
    """A side's largest CPU per wall second of a round, median minor page faults and preemptions per call
    (None where not kept)."""
    return {"cpu_per_wall": t.threads, "page_faults": t.faults, "preempted": t.preempted}


class Record:
    """The numbers of one bench run, as ``--json`` writes them."""

    def __init__(self, config: Config, quick: bool):
        self.data = {"quick": quick, "config": dataclasses.asdict(config), "ratios": {}, "seconds": {},
                     "targets": {}, "details": {}, "compile_seconds": {}, "order": [],
                     "collisions": {}}

    def compare(self, name: str, group: str, what: str, peer: str, steplab: Times, peer_times: Times,
                difference: float | None = None, **details) -> None:
        """Record ratio ``name`` = steplab's median / the peer's, both medians and what was compared.

        The ratio and the seconds beside it (``steplab``, ``peer``, their minimums and
        ``*_spread``: min, median, max of the rounds) are on one clock, ``clock``: CPU
        seconds where both sides ran on one thread, else wall seconds (:func:`clock`).
        Both clocks' ratios and spreads are kept (``ratio_wall``, ``ratio_cpu``,
        ``*_wall_spread``, ``*_cpu_spread``), with each side's CPU per wall second, page
        faults and preemptions per call. ``difference`` is the largest |difference| of the
        two final states (None where the peer computes no state, as for the memory bound).
        ``ratio_stable`` is False where a side's median on the ratio's clock lies more than
        STABILITY["spread"] above its minimum in this run, where fewer than STABILITY["rounds"]
        rounds ran, or where the comparison is known to move (STABILITY["known"], the note why).
        """
        sides = {"steplab": steplab, "peer": peer_times}
        chosen = clock(steplab, peer_times)
        on = {side: t.cpu if chosen == "cpu" else t for side, t in sides.items()}
        notes = [f"{side}'s median {t.median / t.minimum - 1:.0%} above its minimum in this run"
                 for side, t in on.items() if t.median > (1 + STABILITY["spread"]) * t.minimum]
        if min(t.rounds for t in on.values()) < STABILITY["rounds"]:
            notes.append(f"{min(t.rounds for t in on.values())} round(s): no spread to judge")
        if name in STABILITY["known"]:
            notes.insert(0, STABILITY["known"][name])
        self.data["ratios"][name] = on["steplab"].median / on["peer"].median
        self.data["seconds"][name] = {
            "steplab": on["steplab"].median, "peer": on["peer"].median, "peer_name": peer, "group": group,
            "what": what, "difference": difference, "steplab_min": on["steplab"].minimum,
            "peer_min": on["peer"].minimum, "ratio_of_minimums": on["steplab"].minimum / on["peer"].minimum,
            "rounds": steplab.rounds, "clock": chosen, "ratio_wall": steplab.median / peer_times.median,
            "ratio_cpu": None if None in (steplab.cpu, peer_times.cpu) else steplab.cpu.median / peer_times.cpu.median,
            **{f"{side}_spread": _spread(t) for side, t in on.items()},
            **{f"{side}_wall_spread": _spread(t) for side, t in sides.items()},
            **{f"{side}_cpu_spread": None if t.cpu is None else _spread(t.cpu) for side, t in sides.items()},
            **{f"{side}_{key}": value for side, t in sides.items() for key, value in _counts(t).items()},
            "ratio_stable": not notes, "stability_note": "; ".join(notes) or None, **details}
        self.data["order"].append(name)
        self._check_target(name)

    def alias(self, name: str, source: str) -> None:
        """A contract name for another comparison's numbers (e.g. the worse of two problems)."""
        self.data["ratios"][name] = self.data["ratios"][source]
        self.data["seconds"][name] = self.data["seconds"][source] | {"alias_of": source}
        self._check_target(name)

    def _check_target(self, name: str) -> None:
        target = TARGETS.get(name, PEER_TARGETS.get(name))
        if target is not None:
            ratio = self.data["ratios"][name]
            self.data["targets"][name] = {"target": target, "ratio": ratio, "met": ratio <= target}
            source = self.data["seconds"][name].get("alias_of")
            if source is not None:
                self.data["targets"][name]["alias_of"] = source
