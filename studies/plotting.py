"""Shared figure conventions and atomic figure writing (PNG for reading, SVG for the paper)."""

from __future__ import annotations

import io
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
# fixed SVG element ids: the same record gives byte-identical figures
matplotlib.rcParams["svg.hashsalt"] = "steplab"
import matplotlib.pyplot as plt  # noqa: E402

from steplab.io import write_atomic  # noqa: E402

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
    names = []
    for ext in ("png", "svg"):
        buffer = io.BytesIO()
        # no dates or versions in the files: the same record gives the same bytes
        fig.savefig(buffer, format=ext, dpi=150, bbox_inches="tight",
                    metadata={"Date": None} if ext == "svg" else {"Software": None})
        write_atomic(Path(out) / f"{stem}.{ext}", buffer.getvalue())
        names.append(f"{stem}.{ext}")
    plt.close(fig)
    return names
