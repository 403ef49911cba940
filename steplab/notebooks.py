"""The tutorial as Jupyter notebooks, one per lecture topic, each ending with exercises.

One source of truth, two kinds of file:

- ``paper/tutorial.md`` holds the text and the code, section by section (``## 3. ...``);
- ``notebooks/source/<topic>.md`` holds, per topic, a title, the line ``<!-- setup -->``
  (the tutorial's opening code block, without ``matplotlib.use("Agg")``: a notebook shows
  its figures inline), what the topic needs from earlier sections, the line
  ``<!-- tutorial: 3, 8 -->`` (those sections of the tutorial, its figure-only paragraphs
  dropped: the cells above them draw the figures), and the exercises, in jupytext's
  Markdown format: an open exercise is a ```` ```python tags=["exercise"] ```` cell, its
  answer a ```` ```python tags=["solution"] ```` cell.

From those, jupytext builds ``notebooks/<topic>.ipynb`` (the exercises open, the cells
without outputs) and ``notebooks/solutions/<topic>.ipynb`` (each open exercise followed by
its answer). ``python -m steplab.notebooks`` writes both; a test fails when the committed
notebooks differ from what it would write, and another executes the solutions.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from steplab.core.records import write_atomic
from steplab.paper import CODE_BLOCK

SECTION = re.compile(r"^## (\d+)\. ", re.M)
SETUP_MARK = "<!-- setup -->"
TUTORIAL_MARK = re.compile(r"^<!-- tutorial: ([\d, ]+) -->$", re.M)
FIGURE_PARAGRAPH = re.compile(r"^!\[[^\]]*\]\(figures/[^)]+\)\n", re.M)
#: the kernel the notebooks name: any Python 3 kernel with steplab installed
KERNELSPEC = {"name": "python3", "display_name": "Python 3", "language": "python"}
#: which cells each variant keeps, by tag
VARIANTS = {"exercises": {"solution"}, "solutions": set()}


def tutorial_sections(text: str) -> dict[int, str]:
    """The tutorial's numbered sections, number -> Markdown (heading to the next heading)."""
    starts = [(m.start(), int(m.group(1))) for m in SECTION.finditer(text)]
    ends = [s for s, _ in starts[1:]] + [len(text)]
    return {number: text[start:end].rstrip() + "\n" for (start, number), end in zip(starts, ends)}


def notebook_setup(text: str) -> str:
    """The tutorial's opening code block, drawing inline: its ``matplotlib.use`` lines dropped."""
    setup = CODE_BLOCK.findall(text[: SECTION.search(text).start()])[0]
    lines = [line for line in setup.splitlines()
             if line != "import matplotlib" and not line.startswith("matplotlib.use(")]
    # inline figures even where MPLBACKEND names another backend (CI exports Agg)
    return "%matplotlib inline\n" + "\n".join(lines).strip("\n") + "\n"


def topic_markdown(tutorial: str, source: str, label: str = "<source>") -> str:
    """A topic's whole Markdown: ``source`` with its marks replaced from the tutorial's text."""
    if SETUP_MARK not in source or not TUTORIAL_MARK.search(source):
        raise ValueError(f"{label}: needs the lines {SETUP_MARK} and <!-- tutorial: N, ... -->")
    sections = tutorial_sections(tutorial)

    def insert(match):
        numbers = [int(n) for n in match.group(1).replace(" ", "").split(",")]
        unknown = [n for n in numbers if n not in sections]
        if unknown:
            raise ValueError(f"{label}: the tutorial has no section {unknown[0]} (it has {sorted(sections)})")
        return "\n".join(FIGURE_PARAGRAPH.sub("", sections[n]) for n in numbers).rstrip("\n")

    text = source.replace(SETUP_MARK, f"```python\n{notebook_setup(tutorial)}```")
    return TUTORIAL_MARK.sub(insert, text)


def build_notebook(markdown_text: str, variant: str):
    """One variant ("exercises" or "solutions") of a topic as an ``nbformat`` notebook."""
    import jupytext

    notebook = jupytext.reads(markdown_text, fmt="md")
    dropped = VARIANTS[variant]
    notebook.cells = [c for c in notebook.cells if not dropped & set(c.metadata.get("tags", []))]
    for k, cell in enumerate(notebook.cells):
        cell.id = f"cell-{k}"  # fixed ids: the same source gives the same file
    notebook.metadata = {"kernelspec": dict(KERNELSPEC), "language_info": {"name": "python"}}
    return notebook


def notebook_files(tutorial: Path, sources: Path, out: Path) -> dict[Path, str]:
    """Every notebook's path (under ``out``) and text, built from the tutorial and the topic sources."""
    import nbformat

    text = Path(tutorial).read_text()
    files = {}
    for source in sorted(Path(sources).glob("*.md")):
        markdown_text = topic_markdown(text, source.read_text(), str(source))
        for variant, folder in (("exercises", Path(out)), ("solutions", Path(out) / "solutions")):
            files[folder / f"{source.stem}.ipynb"] = nbformat.writes(build_notebook(markdown_text, variant)) + "\n"
    return files


def write_notebooks(tutorial: Path = Path("paper/tutorial.md"), sources: Path = Path("notebooks/source"),
                    out: Path = Path("notebooks")) -> list[Path]:
    """Write every notebook (atomically); return their paths."""
    files = notebook_files(tutorial, sources, out)
    for path, text in files.items():
        write_atomic(path, text.encode())
    return list(files)


def main() -> int:
    if not Path("notebooks/source").is_dir():
        print("python -m steplab.notebooks: run it from the repository root (no notebooks/source here)",
              file=sys.stderr)
        return 2
    for path in write_notebooks():
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
