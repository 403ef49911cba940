"""The tables a study gives the paper: which slice of its record, and how to draw it.

The paper never reads a record's internals itself. A study lists its tables
(``Study.tables``); ``steplab paper`` saves each table's slice into
``paper/data/numbers.json`` and draws the Markdown from that slice alone, so a test can
re-render the committed paper from the committed numbers.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable


@dataclasses.dataclass(frozen=True)
class Table:
    """A table named ``name`` (``{{table:NAME}}`` in the paper's template).

    ``select(record)`` takes the JSON-able slice of the study's record the table needs;
    ``draw(slice)`` writes the Markdown table from that slice alone. A table several
    studies give (the same :class:`Table`, such as the lecture's errors) is drawn from
    their slices, each a list of rows, joined in the order the studies run.
    """

    name: str
    select: Callable[[dict], object]
    draw: Callable[[object], str]

    def within(self, key: str) -> Table:
        """The same table, read from ``record[key]``: a part's table in the record that holds it."""
        return dataclasses.replace(self, select=lambda record: self.select(record[key]))


def markdown_table(header: list[str], rows: list[list[str]]) -> str:
    """A GitHub-flavoured Markdown table (``|`` and ``*`` inside a cell escaped: the lecture's
    formulas, such as ``x = x + (v + a*t)*t``, must not turn into emphasis)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c).replace("|", "\\|").replace("*", "\\*") for c in row) + " |"
              for row in rows]
    return "\n".join(lines)


#: the units a placeholder may print a value in (its spec's last word), from the records' seconds and metres
UNITS = {"ms": 1e3, "us": 1e6, "mm": 1e3}


def format_value(value, spec: str) -> str:
    """A value as the paper prints it: None as "none", booleans as yes/no, else ``format(value, spec)``; a spec
    ending in a unit of :data:`UNITS` prints seconds or metres in it (``.2g ms``: 0.00607 s as "6.1 ms")."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "yes" if value else "no"
    number, _, unit = spec.rpartition(" ")
    if unit in UNITS:
        return f"{format(value * UNITS[unit], number)} {unit}"
    return format(value, spec) if spec else str(value)
