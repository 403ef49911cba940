"""The one atomic writer: whole files or the old ones, also for writers that need a real file."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402
from matplotlib import animation  # noqa: E402
from PIL import Image  # noqa: E402

from steplab.core.records import remove_temporary_files, write_atomic, write_with  # noqa: E402


def test_a_writer_that_fails_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "a.gif"
    write_atomic(target, b"old")

    def half_then_crash(tmp):
        tmp.write_bytes(b"half a fi")
        raise RuntimeError("killed")

    with pytest.raises(RuntimeError, match="killed"):
        write_with(target, half_then_crash)
    assert target.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["a.gif"]


def test_matplotlib_animation_writes_through_a_temporary_file(tmp_path):
    """Pillow picks the format from the temporary's name, so it must end like the target."""
    fig, ax = plt.subplots(figsize=(1, 1))
    line, = ax.plot([0, 1], [0, 0])
    anim = animation.FuncAnimation(fig, lambda k: line.set_ydata([k, -k]), frames=3)
    target = tmp_path / "deep" / "moving.gif"
    try:
        write_with(target, lambda tmp: anim.save(tmp, writer=animation.PillowWriter(fps=5)))
    finally:
        plt.close(fig)
    with Image.open(target) as image:
        assert image.format == "GIF" and image.n_frames == 3
    assert sorted(p.name for p in target.parent.iterdir()) == ["moving.gif"]


def test_leftovers_of_both_temporary_forms_are_removed_and_nothing_else(tmp_path):
    stale = [tmp_path / ".t.json.k2j3h4g5.tmp", tmp_path / ".run.gif.x_81kq.tmp.gif"]
    keep = [tmp_path / "run.gif", tmp_path / "notes.tmp", tmp_path / ".hidden"]
    for path in stale + keep:
        path.write_bytes(b"x")
    assert sorted(remove_temporary_files(tmp_path)) == sorted(stale)
    assert all(path.exists() for path in keep)
