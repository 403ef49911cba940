"""``steplab animate``: MP4 as well as GIF, shared axes, and one line when a format cannot be written."""

import numpy as np
import pytest

from steplab.animate import MAX_SHARED_ZOOM, energy_changes, shared_window
from steplab.cli import main


def test_animate_writes_an_mp4_frame_by_frame(capsys, tmp_path):
    import imageio_ffmpeg

    out = tmp_path / "a.mp4"
    assert main(["animate", "oscillator", "--compare", "euler,velocity-verlet", "--t-end", "0.2", "--fps", "5",
                 "--out", str(out)]) == 0
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    assert frames == 21  # 20 steps of the scene's 10 ms, and the start
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_animate_without_ffmpeg_is_one_line(capsys, tmp_path, monkeypatch):
    import imageio_ffmpeg

    def missing():
        raise RuntimeError("no ffmpeg exe could be found")

    monkeypatch.setattr(imageio_ffmpeg, "get_ffmpeg_exe", missing)
    assert main(["animate", "oscillator", "--out", str(tmp_path / "a.mp4")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "MP4 needs ffmpeg" in err and "Traceback" not in err
    assert not list(tmp_path.iterdir())


def test_panels_share_one_window_that_holds_every_run():
    t = np.linspace(0, 5, 101)[:, None, None]
    steady = np.concatenate([1 + 0.5 * np.cos(2 * np.pi * t), 0 * t], axis=-1)      # +-0.5 m about 1 m
    growing = np.concatenate([1 + 0.5 * np.exp(t) * np.cos(2 * np.pi * t), 0 * t], axis=-1)
    lo, hi = shared_window([steady, growing], np.zeros((0, 2)), 0.05)
    for q in (steady, growing):
        assert (q.reshape(-1, 2) >= lo).all() and (q.reshape(-1, 2) <= hi).all()
    # a run that blew up does not shrink the others to a dot: the window is capped
    blown = steady * 1e30
    lo, hi = shared_window([steady, blown], np.zeros((0, 2)), 0.05)
    assert (hi - lo).max() <= MAX_SHARED_ZOOM * 1.2 * 2


@pytest.mark.parametrize("e0,unit", [(4.0, "% of the initial"), (0.0, "J")])
def test_energy_is_shown_as_its_change(e0, unit):
    changes, shown = energy_changes([np.array([e0, e0 + 1.0]), np.array([e0, e0 - 2.0])])
    scale = 100 / abs(e0) if e0 else 1.0
    assert shown == unit and np.allclose(changes, [[0, scale], [0, -2 * scale]])


@pytest.mark.parametrize(("value", "message"), [
    ("rk4,", "argument --compare: item 2 of 2 in 'rk4,' is empty"),
    ("rk4,,euler", "argument --compare: item 2 of 3 in 'rk4,,euler' is empty"),
])
def test_compare_refuses_an_empty_name(capsys, tmp_path, value, message):
    """``rk4,`` added a panel of the scene's own integrator, as if a name had been typed after the comma."""
    from helpers import refused

    err = refused(capsys, ["animate", "oscillator", "--compare", value, "--out", str(tmp_path / "a.gif")])
    assert err.startswith("steplab animate: error: ") and message in err, err
    assert not list(tmp_path.iterdir())
