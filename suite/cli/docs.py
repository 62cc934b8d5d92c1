"""`python -m suite docs`: rewrite the figures of README.md and docs/ that come from committed files
(the reference run, the tuned settings, the default dataset); `--check` only says which differ.
Either refuses, writing nothing, when a block reads a run whose manifest records a dirty tree or no
commit (one line naming each such manifest, exit 2)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--check", action="store_true",
                   help="write nothing; exit 1 naming every block whose page differs from its data (exit 2 naming "
                        "the manifest when a block reads a run of a dirty tree)")
    p.add_argument("--root", default=".", help="the repository's root (default: the current directory)")


def run(args: argparse.Namespace) -> int:
    from suite.report.docs_blocks import BLOCKS, render

    root = Path(args.root)
    changed = render(root, write=not args.check)
    if args.check:
        for c in changed:
            print(f"differs from its data: {c} (run python -m suite docs)", file=sys.stderr)
        return 1 if changed else 0
    print(f"{len(BLOCKS)} generated blocks; rewritten: {', '.join(changed) if changed else 'none (all current)'}")
    return 0
