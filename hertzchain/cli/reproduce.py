"""`hertzchain reproduce`: regenerate the paper's three figures and its numbers."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..paper.reproduce import reproduce


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="out/reproduce", help="output folder [out/reproduce]")
    parser.add_argument(
        "--quick", action="store_true",
        help="reduced run (three impact velocities, no continuous wall sweep), for checks",
    )


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    print(f"reproducing Job et al., PRL 94, 178002 (2005){' (quick)' if args.quick else ''} ...",
          flush=True)
    numbers = reproduce(out, quick=args.quick)
    print(f"wrote fig1.png, fig2.png, fig3.png, their CSV data, numbers.json and numbers.md "
          f"to {out}")
    width = max(len(row["quantity"]) for row in numbers["rows"])
    for row in numbers["rows"]:
        ours = "-" if row["ours"] is None else f"{row['ours']:.5g}"
        paper = "-" if row["paper"] is None else f"{row['paper']:.5g}"
        difference = row["relative_difference"]
        relative = "" if difference is None else f"{100 * difference:+.2f} %"
        print(f"  {row['quantity']:<{width}}  {ours:>10}  paper {paper:>10}  {relative}")
    return 0
