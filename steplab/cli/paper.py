"""``steplab paper`` and ``steplab report``: the paper and the HTML site, from the study records."""

from __future__ import annotations

from pathlib import Path

from .args import pathname


def add_parser(sub, name: str) -> None:
    if name == "paper":
        p = sub.add_parser(name, help="regenerate paper/paper.md, its figures and HTML from study results")
        p.add_argument("--results", type=pathname, default=Path("results"), help="results folder (default: results/)")
        p.add_argument("--paper-dir", type=pathname, default=Path("paper"), help="paper folder (default: paper/)")
        p.add_argument("--no-tutorial", action="store_true", help="do not re-run the tutorial's code blocks")
        p.add_argument("--pdf", action="store_true", help="also print the HTML to PDF (needs Debian's chromium)")
    else:
        p = sub.add_parser(name, help="write a static HTML site of the results: index, studies, errata, bench")
        p.add_argument("--results", type=pathname, default=Path("results"), help="results folder (default: results/)")
        p.add_argument("--out", type=pathname, required=True,
                       help="site folder (serve with python -m http.server -d DIR)")


def command(args) -> int:
    if args.command == "report":
        from steplab.report import build, main_summary

        print(main_summary(build(args.results, args.out)))
        return 0
    from steplab.paper import build

    if not (args.paper_dir / "paper.template.md").exists():
        raise ValueError(f"--paper-dir {args.paper_dir}: no paper.template.md there (run from the repository root)")
    for path in build(args.results, args.paper_dir, tutorial=not args.no_tutorial, pdf=args.pdf):
        print(f"wrote {path}")
    return 0
