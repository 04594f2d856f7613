"""The benchmark scripts answer bad input as the app's commands do: one `error:` line and exit 2, no traceback,
nothing written (a missing dir, a run of the wrong kind, a count of 0 or below, a directory given as an output file,
a malformed --goal). Each script parses with `Parser`, checks every input before it writes anything, and runs its
main through `run` (ppo_torchrl.errors' one error path: ConfigError exit 2, a full disk exit 1, a bug an internal
error line with its traceback in a log file)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from ppo_torchrl.errors import ConfigError, guarded


class Parser(argparse.ArgumentParser):
    """argparse, its refusals one line: `error: argument --episodes: must be >= 1, not 0; usage: ...`."""

    def error(self, message: str):
        usage = " ".join(self.format_usage().split()).removeprefix("usage: ")
        print(f"error: {message}; usage: {usage}", file=sys.stderr, flush=True)
        raise SystemExit(2)


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, not {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, not {value}")
    return value


def seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, not {text!r}") from None
    if not 0 <= value < 2**32 // 1000:
        raise argparse.ArgumentTypeError(f"must be in 0..{2**32 // 1000 - 1} (episode i starts from seed * 1000 + i), "
                                         f"not {value}")
    return value


def finite(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, not {text!r}")
    return value


def existing_dir(text: str) -> Path:
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such directory" if not path.exists() else f"{text} is a file, "
                                         "not a run dir")
    return path


def out_file(text: str) -> Path:
    """A file to write: not a directory, in a folder that exists (nothing is made on the way)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a directory; give the file to write, e.g. {path / 'table.md'}")
    if not path.parent.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: its folder {path.parent} does not exist")
    return path


def out_dir(text: str) -> Path:
    """A folder to write into (made when missing): not a file."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; give a directory")
    return path


def goal(text: str) -> tuple:
    """--goal <robot>=<share at 0.25 l in (0, 1]>, e.g. go1=0.9."""
    robot, sep, share = text.partition("=")
    try:
        value = float(share)
    except ValueError:
        value = math.nan
    if not sep or not robot or not 0 < value <= 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected <robot>=<share of episodes in (0, 1]>, e.g. go1=0.9")
    return robot, value


def run(main, argv=None) -> int:
    """main(argv) through the app's one error path; its exit code."""
    code = guarded(main, sys.argv[1:] if argv is None else argv)
    return 0 if code is None else code


__all__ = ["ConfigError", "Parser", "existing_dir", "finite", "goal", "out_dir", "out_file", "positive_int", "run",
           "seed"]
