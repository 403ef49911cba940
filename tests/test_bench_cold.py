"""The bench's cold-cache timing (steplab/bench/cold.py), under which the xpbd cloth meets its memory bound."""

from __future__ import annotations

from steplab.bench import cold


def test_every_timed_call_follows_an_eviction_and_is_made_once():
    events = []
    calls = {"step": lambda: events.append("step"), "bound": lambda: events.append("bound")}
    samples = cold.cold_samples(calls, 3, lambda: events.append("evict"))
    assert events == ["evict", "step", "evict", "bound"] * 3
    assert {name: (len(s), len(s.cpu), s.number) for name, s in samples.items()} == {"step": (3, 3, 1),
                                                                                        "bound": (3, 3, 1)}


def test_the_eviction_reads_several_times_the_largest_cache(monkeypatch, tmp_path):
    for index, size in enumerate(["48K", "1024K", "32768K"]):
        (tmp_path / f"index{index}").mkdir()
        (tmp_path / f"index{index}" / "size").write_text(size + "\n")
    monkeypatch.setattr(cold.glob, "glob", lambda pattern: [str(p / "size") for p in sorted(tmp_path.iterdir())])
    assert cold.largest_cache_bytes() == 32 * 2**20
    evict = cold.evictor(factor=2)
    assert evict.__self__.nbytes == 64 * 2**20 and evict() == 8 * 2**20  # a sum of ones: every byte read
    monkeypatch.setattr(cold.glob, "glob", lambda pattern: [])
    assert cold.largest_cache_bytes() == cold.DEFAULT_CACHE_BYTES  # no sysfs: this machine's L3
