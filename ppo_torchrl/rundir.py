"""Run dirs are owned: one run per dir, one process per dir at a time.

- A new run needs a dir that does not exist or is empty. A dir that holds a run (its metrics.csv,
  summary.json, checkpoints/, or config.yaml beside .hydra/) is refused unless `overwrite=true`, which removes that
  run's files first; a non-empty dir that holds no run is refused always (it is somebody's files).
- `resume=<dir>` continues the run in its own dir.
- A lock (`<dir>/.lock`, an OS file lock held for the life of the process, released even by kill -9)
  stops a second process from writing into a dir in use; the refusal names the other process.

`claim()` runs before Hydra or the app writes anything, so a refused command changes nothing.
"""

from __future__ import annotations

import fcntl
import os
import shutil
from pathlib import Path

from ppo_torchrl.errors import ConfigError

LOCK = ".lock"
RUN_MARKERS = ("metrics.csv", "summary.json", "checkpoints")  # and config.yaml beside .hydra/
# What a run writes into its dir (Hydra's too): what overwrite=true removes, and nothing else.
RUN_FILES = RUN_MARKERS + ("config.yaml", ".hydra", "logs", "videos", "eval", "report.png", "policy.pt", "error.log",
                           "__main__.log", "multirun.yaml")

_held: dict = {}  # dir -> open lock file, kept for the life of the process


def holds_run(directory: Path) -> bool:
    directory = Path(directory)
    return any((directory / name).exists() for name in RUN_MARKERS) or (
        (directory / "config.yaml").exists() and (directory / ".hydra").exists())


def _is_sweep_of_runs(directory: Path) -> bool:
    return (directory / "multirun.yaml").exists() or any(
        holds_run(child) for child in directory.iterdir() if child.is_dir())


def check_new_dir(directory: Path, overwrite: bool, what: str = "run") -> None:
    """Refuse a dir that holds a run (or a sweep of runs) unless overwrite; refuse foreign files."""
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise ConfigError(f"the {what} dir {directory} is a file; give hydra.run.dir (or hydra.sweep.dir) a directory")
    if not directory.is_dir():
        return
    entries = [p for p in directory.iterdir() if p.name != LOCK]
    if not entries:
        return
    has_run = holds_run(directory) if what == "run" else _is_sweep_of_runs(directory)
    key = "hydra.run.dir" if what == "run" else "hydra.sweep.dir"
    if has_run and not overwrite:
        hint = f"continue it with resume={directory}, " if what == "run" else ""
        raise ConfigError(f"{directory} already holds a {what}: {hint}pick a new dir with {key}=<dir>, "
                          "or replace it with overwrite=true")
    foreign = [p.name for p in entries if (p.name not in RUN_FILES if what == "run" else not p.is_dir())]
    if foreign and not (what == "sweep" and has_run):
        raise ConfigError(f"{directory} is not empty and is not a ppo_torchrl {what} dir (it holds {', '.join(sorted(foreign)[:3])}); "
                          f"pick an empty or new dir with {key}=<dir>")


def lock(directory: Path) -> None:
    """Take the dir's lock for this process, or fail naming the process that holds it."""
    directory = Path(directory).resolve()
    if directory in _held:
        return
    try:
        directory.mkdir(parents=True, exist_ok=True)
        handle = open(directory / LOCK, "a+")
    except OSError as exc:
        raise ConfigError(f"cannot write the run dir {directory}: {exc.strerror or exc}") from None
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        handle.seek(0)
        holder = handle.read().strip() or "another process"
        handle.close()
        raise ConfigError(f"{directory} is in use by {holder}; wait for it to end or pick another dir") from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"pid {os.getpid()}\n")
    handle.flush()
    _held[directory] = handle


def remove_run_files(directory: Path) -> None:
    """overwrite=true: remove the previous run's files (only the names a run writes)."""
    for name in RUN_FILES:
        path = Path(directory) / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()


def remove_sweep_runs(directory: Path) -> None:
    for child in Path(directory).iterdir():
        if child.is_dir() and (holds_run(child) or (child / ".hydra").exists()):
            shutil.rmtree(child)
    remove_run_files(directory)


def claim(directory: Path, *, overwrite: bool = False, resume: bool = False, what: str = "run") -> Path:
    """Check the dir (see the module doc), then lock it; with overwrite, clear the old run once locked."""
    directory = Path(directory).expanduser()
    if directory.resolve() in _held:  # claimed already by this process (before Hydra started)
        return directory
    if not resume:
        check_new_dir(directory, overwrite, what)
    lock(directory)
    if overwrite and not resume:
        (remove_run_files if what == "run" else remove_sweep_runs)(directory)
    return directory
