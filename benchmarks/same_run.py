"""Do two runs give the same training numbers? Compares two run dirs' metrics.csv cell by cell (the
wall-clock columns time_s and sps left out) and prints a markdown summary.

    .venv/bin/python benchmarks/same_run.py <run dir A> <run dir B> [--tolerance 0]
"""

import argparse
import csv
from pathlib import Path

from ppo_torchrl.records import open_record

WALL_CLOCK = {"time_s", "sps"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("a", type=Path)
    parser.add_argument("b", type=Path)
    parser.add_argument("--tolerance", type=float, default=0.0, help="relative; 0: the printed values must be equal")
    args = parser.parse_args()
    rows_a = list(csv.DictReader(open_record(args.a / "metrics.csv", newline="")))
    rows_b = list(csv.DictReader(open_record(args.b / "metrics.csv", newline="")))
    columns = [c for c in rows_a[0] if c not in WALL_CLOCK and c in rows_b[0]]
    differ = []
    for ra, rb in zip(rows_a, rows_b):
        for c in columns:
            x, y = ra[c], rb[c]
            if x == y:
                continue
            if x and y and abs(float(x) - float(y)) <= args.tolerance * max(abs(float(x)), abs(float(y))):
                continue
            differ.append((ra["iteration"], c, x, y))
    cells = min(len(rows_a), len(rows_b)) * len(columns)
    print(f"- A: `{args.a}` ({len(rows_a)} rows), B: `{args.b}` ({len(rows_b)} rows); columns compared: "
          f"{len(columns)} (all but {', '.join(sorted(WALL_CLOCK))}), cells: {cells:,}")
    print(f"- cells that differ: **{len(differ)}**" + (f" (relative tolerance {args.tolerance})" if args.tolerance else ""))
    if differ:
        print("\n| iteration | column | A | B |\n|---|---|---|---|")
        for row in differ[:50]:
            print("| " + " | ".join(row) + " |")
    only = sorted(set(rows_a[0]) ^ set(rows_b[0]))
    if only:
        print(f"- columns in one file only: {', '.join(only)}")


if __name__ == "__main__":
    main()
