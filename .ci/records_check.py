#!/usr/bin/env python3
"""The repository stays one a user clones in seconds (results/README.md, "What results/ keeps").

    python3 .ci/records_check.py [repo dir]

Fails (exit 1, one line per finding) when a tracked file is over 1 MB and not on .ci/large_files.txt, when the
tracked tree is over 40 MiB (what `git ls-files -z | xargs -0 du -cb` sums), when results/ tracks code (a .py file:
results/ holds records; the scripts that made them live in benchmarks/), or when it tracks a training row's working
files, its raw `metrics.csv` or its `checkpoints/best.pt`: .gitignore lets both stand untracked beside a row that is
still training, so that a move of the checkout to a new machine (which carries untracked files, not ignored ones)
keeps the row's whole curve and its best checkpoint; the records are `metrics.csv.xz` and `checkpoints/last.pt`. `make test` runs it on every
submission (tests/test_records.py), so CI fails on either.
"""

import subprocess
import sys
from pathlib import Path

FILE_LIMIT = 1_000_000  # bytes: a newly tracked file over this needs a line in .ci/large_files.txt
TREE_LIMIT = 40 * 2**20  # bytes: 40 MiB for everything tracked


def allowed(repo: Path) -> set:
    listed = repo / ".ci" / "large_files.txt"
    if not listed.is_file():
        return set()
    lines = (line.split("#", 1)[0].strip() for line in listed.read_text().splitlines())
    return {line for line in lines if line}


def working_file(name: str) -> bool:
    return name.endswith("/metrics.csv") or name.endswith("/checkpoints/best.pt")


def findings(repo: Path) -> list:
    names = subprocess.run(["git", "-C", str(repo), "ls-files", "-z"], check=True, capture_output=True).stdout
    sizes = {}
    for name in names.decode().split("\0"):
        path = repo / name
        if name and path.is_file() and not path.is_symlink():
            sizes[name] = path.stat().st_size
    ok = allowed(repo)
    out = [f"{name} is {size / 1e6:.1f} MB (limit 1 MB): keep it out of git, or add it to .ci/large_files.txt with why"
           for name, size in sorted(sizes.items()) if size > FILE_LIMIT and name not in ok]
    out += [f"{name} is code under results/, which holds records: move it to benchmarks/ (and fix what names it)"
            for name in sorted(sizes) if name.startswith("results/") and name.endswith(".py")]
    out += [f"{name} is a training row's working file: commit its record instead (the curve as "
            "metrics.csv.xz: `xz -9`, then benchmarks/thin_metrics.py once the row is finished; checkpoints/last.pt)"
            for name in sorted(sizes) if name.startswith("results/") and working_file(name)]
    total = sum(sizes.values())
    if total > TREE_LIMIT:
        out.append(f"the tracked tree is {total / 2**20:.1f} MiB (budget 40 MiB): results/ keeps records, not run "
                   "folders (results/README.md)")
    return out


def main(argv: list) -> int:
    repo = Path(argv[0]) if argv else Path(__file__).resolve().parents[1]
    found = findings(repo)
    for line in found:
        print(f"records check: {line}", file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
