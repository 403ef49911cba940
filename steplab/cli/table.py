"""Aligned text tables: every column as wide as its widest cell, whatever the names' lengths."""

from __future__ import annotations


def table(rows, header: tuple[str, ...] | None = None, right: tuple[int, ...] = (), indent: str = "") -> str:
    """``rows`` (tuples of strings, under an optional ``header``) as aligned lines; the columns
    numbered in ``right`` (numbers) are right-aligned, the others left."""
    lines = ([tuple(header)] if header else []) + [tuple(row) for row in rows]
    if not lines:
        return ""
    widths = [max(len(line[k]) for line in lines) for k in range(len(lines[0]))]
    return "\n".join(indent + "  ".join(text.rjust(w) if k in right else text.ljust(w)
                                        for k, (text, w) in enumerate(zip(line, widths))).rstrip()
                     for line in lines)
