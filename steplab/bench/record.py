"""The record of one bench run: every comparison's ratio, medians, minimums and what was compared."""

from __future__ import annotations

import dataclasses

import numpy as np

from steplab.core.timing import Times

from .config import PEER_TARGETS, STABILITY, TARGETS, Config


def final_difference(a, b) -> float:
    """Largest |difference| of two final states (positions and velocities), or of two arrays."""
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float)), initial=0.0))


def size_label(n: int) -> str:
    """A size in a comparison's name: ``1e5`` for a power of ten, else the number (``2000``)."""
    e = int(round(np.log10(n)))
    return f"1e{e}" if 10**e == n else str(n)


class Record:
    """The numbers of one bench run, as ``--json`` writes them."""

    def __init__(self, config: Config, quick: bool):
        self.data = {"quick": quick, "config": dataclasses.asdict(config), "ratios": {}, "seconds": {},
                     "targets": {}, "details": {}, "compile_seconds": {}, "order": [],
                     "collisions": {}}

    def compare(self, name: str, group: str, what: str, peer: str, steplab: Times, peer_times: Times,
                difference: float | None = None, **details) -> None:
        """Record ratio ``name`` = steplab's median / the peer's, both medians and what was compared.

        ``difference`` is the largest |difference| of the two final states (None where the
        peer computes no state, as for the memory bound). Each side's spread over its rounds
        (min, median, max) is kept, and whether the ratio can be trusted: ``ratio_stable``
        is False where a side's median lies more than STABILITY["spread"] above its minimum
        in this run, or where the comparison is known to move (STABILITY["known"], the note why).
        """
        spreads = {side: {"min": t.minimum, "median": t.median, "max": t.maximum, "rounds": t.rounds}
                   for side, t in (("steplab", steplab), ("peer", peer_times))}
        notes = [f"{side}'s median {s['median'] / s['min'] - 1:.0%} above its minimum in this run"
                 for side, s in spreads.items() if s["median"] > (1 + STABILITY["spread"]) * s["min"]]
        if name in STABILITY["known"]:
            notes.insert(0, STABILITY["known"][name])
        self.data["ratios"][name] = steplab.median / peer_times.median
        self.data["seconds"][name] = {
            "steplab": steplab.median, "peer": peer_times.median, "peer_name": peer, "group": group, "what": what,
            "difference": difference, "steplab_min": steplab.minimum, "peer_min": peer_times.minimum,
            "ratio_of_minimums": steplab.minimum / peer_times.minimum, "rounds": steplab.rounds,
            "steplab_spread": spreads["steplab"], "peer_spread": spreads["peer"],
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
