"""Records as `results/` keeps them: a run's text tables may be stored xz-compressed under their name plus `.xz`.

A 10M-frame run's `metrics.csv` is ~1 MB of text and ~0.3 MB as `metrics.csv.xz` (the stdlib's lzma, `xzcat` reads
it too); `results/README.md` says which records are kept that way. Every reader of a record (report, the table
scripts in benchmarks/) opens it through `open_record`, which takes the plain file when there is one and the
`.xz` one otherwise, so a run dir under `outputs/` and its record under `results/` read the same.
`compress` writes the `.xz` beside a plain file and leaves the plain one as it is (records.main: the command).
A record taken mid-run (a run committed as it stood, then resumed) holds a prefix of the log the run goes on
writing: `compress` brings it up to date; a record of any other text is refused, never replaced.
A reported row's final checkpoint is kept as a record checkpoint (`record_checkpoint`): its weights, statistics,
config and counters without the optimizer's state (two thirds of the file), enough to evaluate, export, load and
init_from it, not to resume it.
"""

from __future__ import annotations

import io
import lzma
from pathlib import Path
from typing import IO, Union

SUFFIX = ".xz"


def record_path(path: Union[str, Path]) -> Path:
    """`path` when it is a file, else its `.xz` twin when that is one, else `path` (a reader's error names it)."""
    path = Path(path)
    packed = path.with_name(path.name + SUFFIX)
    return packed if not path.is_file() and packed.is_file() else path


def has_record(path: Union[str, Path]) -> bool:
    return record_path(path).is_file()


def open_record(path: Union[str, Path], newline: str = None) -> IO[str]:
    """A text handle on the record (plain or xz-compressed), as `open(path, newline=newline)` gives one."""
    found = record_path(path)
    if found.name.endswith(SUFFIX) and not Path(path).name.endswith(SUFFIX):
        return io.TextIOWrapper(lzma.open(found, "rb"), encoding="utf-8", newline=newline)
    return open(found, newline=newline, encoding="utf-8")


def read_record_text(path: Union[str, Path]) -> str:
    with open_record(path) as f:
        return f.read()


def compress(path: Union[str, Path]) -> Path:
    """Write `<path>.xz` (xz -9, no timestamps: the same bytes from the same text) beside `path`, which stays.
    An `.xz` there already is kept when it holds this text, updated when it holds a prefix of it (the same log,
    recorded earlier in the run), refused otherwise (another text, or not xz at all). Inside a run dir the record is
    the app's file like evaluate's outputs: listed in the run's manifest with its bytes' sha256 (write-ahead, then
    renamed into place), so overwrite=true takes the run whole, and an update replaces only a record the app wrote."""
    from ppo_torchrl.run.ownership import holder
    from ppo_torchrl.run.rundir import atomic_write_bytes, check_replaceable, record

    path = Path(path)
    out = path.with_name(path.name + SUFFIX)
    text = path.read_bytes()
    run = holder(out)
    if out.exists():
        try:
            old = lzma.decompress(out.read_bytes()) if out.is_file() else None
        except (lzma.LZMAError, EOFError):
            old = None
        if old == text:
            return out  # already this record
        if not old or not text.startswith(old):  # not a file, empty, not xz, or another text
            raise FileExistsError(f"{out} exists and holds another text; move it away first")
        if run is not None:
            check_replaceable(run, [out])  # a prefix the user put in a run dir is theirs: one line, left as it is
    data = lzma.compress(text, preset=9 | lzma.PRESET_EXTREME)
    # a temp file of a name of its own beside it (mkstemp), renamed over `out`; a failed write removes it
    atomic_write_bytes(out, lambda f: f.write(data), owner=run)
    if run is not None:
        record(run, [out])
    return out


RECORD = "record"  # the key a record checkpoint carries: what it left out


def record_checkpoint(path: Union[str, Path]) -> Path:
    """Rewrite the checkpoint at `path` as a record checkpoint, in place (atomic): without the optimizer's state."""
    from ppo_torchrl.run import checkpoint

    state = checkpoint.load(path)
    if state.pop("optimizer", None) is not None or RECORD not in state:
        state[RECORD] = "weights, statistics, config and counters; no optimizer state: evaluate, export, init_from"
        checkpoint.save(Path(path), state)
    return Path(path)


USAGE = ("python -m ppo_torchrl.records FILE [...]  (writes FILE.xz beside each; FILE stays; a .pt checkpoint loses "
         "its optimizer state in place)")


def main(argv: list) -> int:
    """python -m ppo_torchrl.records FILE [...]: each FILE's `.xz` record beside it (the plain file stays); a
    checkpoint (`.pt`) is made a record checkpoint in place. A FILE inside a run dir is written under the run's lock,
    taken exclusive (locks.hold): a run training there, or an evaluate reading it, refuses the command before it
    writes anything. Bad input is ConfigError (one line, exit 2 through cli.run); an OSError (a full disk, a file-size
    limit) is the app's one line, and no temp file stays."""
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.locks import hold, release_reads
    from ppo_torchrl.run.ownership import holder

    if not argv or any(a.startswith("-") for a in argv):
        raise ConfigError(f"{'no FILE given' if not argv else repr(next(a for a in argv if a.startswith('-')))}; "
                          f"usage: {USAGE}")
    missing = [a for a in argv if not Path(a).is_file()]
    if missing:
        raise ConfigError(f"{missing[0]} is not a file")
    try:
        for run in dict.fromkeys(holder(a) for a in argv):  # every run's lock before anything is written
            hold(run, "records writes into a run dir")
        for a in argv:
            try:
                print(f"wrote {record_checkpoint(a) if a.endswith('.pt') else compress(a)}", flush=True)
            except FileExistsError as e:
                raise ConfigError(str(e)) from None
    finally:
        release_reads()
    return 0


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
