#!/usr/bin/env python3
"""Fails when the README or a reference doc quotes a figure of the kinds docs/results.md reports
(acknowledged frames/s, placements, giant objects, recall, purity) with a value that
docs/results.md does not hold: such figures are measured by scripts/figures.py and linked, not
copied (a copy goes stale the day the code changes).

    scripts/check_docs.py [--results FILE] [DOC...]

Default DOCs: README.md and docs/{server,python,web,architecture}.md. docs/gsm.md,
docs/database.md and docs/structure.md still keep dated measurements of their experiments and
are not checked yet (issue 47, item 5). Prints each stale figure as "FILE:LINE: ..." and exits 1
if there is any; 0 and "ok" otherwise.
"""

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOCS = ["README.md", "docs/server.md", "docs/python.md", "docs/web.md", "docs/architecture.md"]

# A figure of results.md's kinds, the value in group 1.
FIGURES = [
    ("acknowledged frames/s", r"(\d+(?:\.\d+)?) acknowledged frames/s"),
    ("placements", r"\b(\d+) placements\b"),
    ("giant objects", r"\b(\d+) giant objects?\b"),
    ("recall", r"\b(\d+ % \(\d+ of \d+\)) of repeated kinds"),
    ("recall", r"\brecall (\d+ %)"),
    ("purity", r"\bpurity (\d+ %)"),
]


def main(argv) -> int:
    args = list(argv)
    results_path = ROOT / "docs" / "results.md"
    if "--results" in args:
        i = args.index("--results")
        results_path = Path(args[i + 1])
        del args[i:i + 2]
    docs = [Path(a) for a in args] or [ROOT / d for d in DOCS]
    results = results_path.read_text()
    problems = []
    for doc in docs:
        for number, line in enumerate(doc.read_text().splitlines(), 1):
            for kind, pattern in FIGURES:
                for m in re.finditer(pattern, line):
                    if m.group(1) not in results:
                        problems.append(f"{doc}:{number}: quotes {kind} '{m.group(0)}', which is "
                                        f"not in {results_path.name}: link to it instead")
    for p in problems:
        print(p)
    if problems:
        return 1
    print(f"ok: {len(docs)} docs quote no figure that {results_path.name} does not hold")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
