#!/usr/bin/env python3
"""Fails when the README or a reference doc quotes a figure of the kinds docs/results.md reports
(acknowledged frames/s, placements, giant objects, recall, purity) with a value that
docs/results.md does not hold: such figures are measured by scripts/figures.py and linked, not
copied (a copy goes stale the day the code changes).

    scripts/check_docs.py [--results FILE] [DOC...] [--reference DOC...]

Default DOCs: README.md and docs/{server,python,web,architecture}.md, and, as reference pages,
docs/{gsm,database,structure}.md. A reference page describes rules and parameters; the
measurements that chose them are dated in docs/experiments.md (not checked). So a reference page
is held to more kinds of figure as well: measured times (s, ms, µs, min), rates (frames/s),
counts "N of M", completion gains "+N points", and any date (YYYY-MM-DD) at all. DOCs after
--reference are checked as reference pages. Prints each stale figure as "FILE:LINE: ..." and
exits 1 if there is any; 0 and "ok" otherwise.
"""

import argparse
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ["README.md", "docs/server.md", "docs/python.md", "docs/web.md", "docs/architecture.md"]
REFERENCE_DOCS = ["docs/gsm.md", "docs/database.md", "docs/structure.md"]

# A figure of results.md's kinds, the value in group 1.
FIGURES = [
    ("acknowledged frames/s", r"(\d+(?:\.\d+)?) acknowledged frames/s"),
    ("placements", r"\b(\d+) placements\b"),
    ("giant objects", r"\b(\d+) giant objects?\b"),
    ("recall", r"\b(\d+ % \(\d+ of \d+\)) of repeated kinds"),
    ("recall", r"\brecall (\d+ %)"),
    ("purity", r"\bpurity (\d+ %)"),
]

# In a reference page, also these measured figures (value in group 1).
REFERENCE_FIGURES = [
    ("a time", r"(?<![\w.,])(\d+(?:[.,]\d+)*)(?:\s*[–-]\s*\d+(?:[.,]\d+)*)? ?(?:s|ms|µs|min)\b(?!/)"),
    ("a rate", r"(?<![\w.,])(\d+(?:[.,]\d+)*) (?:\w+ )?frames?/s\b"),
    ("a count", r"(?<![\w.,])(\d+(?:,\d+)* of \d+(?:,\d+)*)\b"),
    ("a completion gain", r"(\+\d+(?:\.\d+)?)(?: points|\s*→)"),
]

# Never in a reference page: dated material is history and goes to docs/experiments.md.
DATE = re.compile(r"\b20\d\d-\d\d-\d\d\b")


def held(value: str, results: str) -> bool:
    """Whether results.md holds `value` as a figure of its own (not as part of a longer one)."""
    return re.search(r"(?<![\d.,])" + re.escape(value) + r"(?![\d,]|\.\d)", results) is not None


def main(argv) -> int:
    parser = argparse.ArgumentParser(description="Docs quote no figure docs/results.md lacks.")
    parser.add_argument("docs", nargs="*", type=Path)
    parser.add_argument("--results", type=Path, default=ROOT / "docs" / "results.md")
    parser.add_argument("--reference", nargs="*", type=Path, default=[])
    args = parser.parse_args(argv)
    results_path, plain, reference = args.results, args.docs, args.reference
    if not plain and not reference:
        plain = [ROOT / d for d in DOCS]
        reference = [ROOT / d for d in REFERENCE_DOCS]
    results = results_path.read_text()
    problems = []
    checks = [(doc, FIGURES, False) for doc in plain]
    checks += [(doc, FIGURES + REFERENCE_FIGURES, True) for doc in reference]
    for doc, figures, is_reference in checks:
        for number, line in enumerate(doc.read_text().splitlines(), 1):
            for kind, pattern in figures:
                for m in re.finditer(pattern, line):
                    if not held(m.group(1), results):
                        problems.append(f"{doc}:{number}: quotes {kind} '{m.group(0)}', which is "
                                        f"not in {results_path.name}: link to it instead (or "
                                        f"date it in experiments.md)")
            if is_reference:
                for m in DATE.finditer(line):
                    problems.append(f"{doc}:{number}: dated '{m.group(0)}': a reference page "
                                    f"holds no history; it goes to experiments.md")
    for p in problems:
        print(p)
    if problems:
        return 1
    print(f"ok: {len(plain)} docs and {len(reference)} reference pages quote no figure that "
          f"{results_path.name} does not hold")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
