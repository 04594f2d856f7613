"""Thin a finished row's committed `metrics.csv.xz` to what its records are read for, so that the tracked tree stays
under 40 MiB as reported rows land (results/README.md, "What results/ keeps"). Repository upkeep, not the app.

    python benchmarks/thin_metrics.py results/robots/legged_v2_2026-11-28/*/metrics.csv.xz [--every 10]

Kept of each file, every column as it was: the header; the first and the last iteration; every --every-th iteration;
every row with an in-training eval (any `eval/` value); every row where `env/terrain_level` differs from the row
before (so the frame a curriculum first reached a level, which benchmarks/robots_table.py reads, stays exact).
`report` and the table scripts read a thinned file as they read a whole one (the curves at a tenth of the points).
The whole file stays in git history (`git show <commit>:<path>`). Each file is rewritten through a temp file beside
it and renamed into place; a file that is already thinned (no row left to drop) is left as it is. Not for a run
still training: the app updates a record taken mid-run only when it is a prefix of the log (records.py), which a
thinned file is not, so it refuses it rather than replace it.
"""

from __future__ import annotations

import argparse
import csv
import io
import lzma
import os
import sys
import tempfile
from pathlib import Path


def thin_rows(rows: list, header: list, every: int) -> list:
    it, level = header.index("iteration"), header.index("env/terrain_level") if "env/terrain_level" in header else None
    evals = [i for i, name in enumerate(header) if name.startswith("eval/")]
    kept, last_level = [], None
    for n, row in enumerate(rows):
        lvl = row[level] if level is not None and level < len(row) else None
        keep = (n in (0, len(rows) - 1) or int(row[it]) % every == 0 or any(i < len(row) and row[i] for i in evals)
                or lvl != last_level)
        last_level = lvl
        if keep:
            kept.append(row)
    return kept


def thin(path: Path, every: int) -> tuple:
    text = lzma.decompress(path.read_bytes()).decode()
    table = list(csv.reader(io.StringIO(text)))
    header, rows = table[0], table[1:]
    kept = thin_rows(rows, header, every)
    if len(kept) == len(rows):
        return len(rows), len(kept), path.stat().st_size, path.stat().st_size
    out = io.StringIO()
    csv.writer(out, lineterminator="\n").writerows([header, *kept])
    data = lzma.compress(out.getvalue().encode(), preset=9 | lzma.PRESET_EXTREME)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        before = path.stat().st_size
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(rows), len(kept), before, len(data)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="+", type=Path)
    parser.add_argument("--every", type=int, default=10)
    args = parser.parse_args(argv)
    bad = [f for f in args.files if not f.is_file() or not f.name.endswith("metrics.csv.xz")]
    if bad or args.every < 2:
        print(f"error: {bad[0]} is not a metrics.csv.xz file" if bad else "error: --every must be >= 2", file=sys.stderr)
        return 2
    total = [0, 0]
    for f in args.files:
        rows, kept, before, after = thin(f, args.every)
        total[0] += before
        total[1] += after
        print(f"{f}: {rows} -> {kept} rows, {before / 1e3:.0f} -> {after / 1e3:.0f} KB")
    print(f"all: {total[0] / 1e6:.2f} -> {total[1] / 1e6:.2f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
