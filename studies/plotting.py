"""Shared figure conventions and atomic figure writing (PNG for reading, SVG for the paper)."""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

#: one colour and marker per integrator, so a method looks the same in every figure
STYLE = {
    "euler": ("tab:red", "o"),
    "semi-implicit-euler": ("tab:orange", "s"),
    "velocity-verlet": ("tab:green", "^"),
    "position-verlet": ("tab:olive", "v"),
    "heun": ("tab:purple", "D"),
    "midpoint": ("tab:pink", "P"),
    "rk4": ("tab:blue", "*"),
    "implicit-euler": ("tab:brown", "X"),
}


def style(name: str) -> dict:
    colour, marker = STYLE.get(name, ("tab:gray", "."))
    return {"color": colour, "marker": marker, "label": name}


def save_figure(fig, out: Path, stem: str) -> list[str]:
    """Write ``stem.png`` and ``stem.svg`` into ``out`` atomically; return their names."""
    out.mkdir(parents=True, exist_ok=True)
    names = []
    for ext in ("png", "svg"):
        target = out / f"{stem}.{ext}"
        fd, tmp = tempfile.mkstemp(dir=out, prefix=f".{stem}.", suffix=f".{ext}")
        os.close(fd)
        try:
            fig.savefig(tmp, format=ext, dpi=150, bbox_inches="tight",
                        metadata={"Date": None} if ext == "svg" else {"Software": None})
            os.replace(tmp, target)
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise
        names.append(target.name)
    plt.close(fig)
    return names
