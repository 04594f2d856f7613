"""Who holds a run dir, and the readers' lock: evaluate, export and report hold a shared lock on the run dir
they read (and on a run dir they write into with out=) while they run.

A writer (a run, a resume, an overwrite: rundir.lock) takes the dir's `flock` exclusive; a reader takes it
shared. So an overwrite or a new run refuses while a reader holds the dir (it would get the old policy's
eval.json in the new run's dir), readers run side by side, and a reader refuses while a run trains there.
Nothing is written: the lock is on the dir's descriptor, released by the process's end, kill -9 included.
`records` rewrites a run's own files (a record checkpoint in place, `metrics.csv.xz` beside its log): it holds the
dir's lock exclusive (`hold`), so it refuses a run still training there (its record checkpoint would leave a run that
cannot resume) and a reader, and a run cannot start there while it writes.
"""

from __future__ import annotations

import fcntl
import functools
import os
from pathlib import Path
from typing import List, Optional

from ppo_torchrl.errors import ConfigError

_reading: List[int] = []  # descriptors holding a lock (shared; `hold`: exclusive) for the entry point now running


def holder(directory: Path) -> str:
    """Who holds the dir's lock, from /proc/locks (Linux): 'pid N' (a writer) or 'pid N, which is reading it
    (evaluate, export or report)'; 'another process' when it cannot be told."""
    try:
        st = os.stat(directory)
        dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
        for line in Path("/proc/locks").read_text().splitlines():
            parts = line.split()
            if "FLOCK" in parts and parts[-3] == dev and "->" not in parts:
                reading = " (evaluate, export or report reading it)" if parts[-5] == "READ" else ""
                return f"pid {parts[-4]}{reading}"
    except (OSError, IndexError, ValueError):
        pass
    return "another process"


def read(directory: Optional[Path]) -> None:
    """Hold a shared lock on `directory` until the entry point ends (`releasing`), or refuse in one line while
    another process writes there. A dir this process itself holds for writing, one that is not there, or a
    filesystem without locks: read without one."""
    if directory is None or not Path(directory).is_dir():
        return
    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        if _mine(directory):
            return  # this process writes there (a run that evaluates its own dir)
        raise ConfigError(f"{directory} is in use by {holder(directory)}, which is writing there (a run training, or one replacing "
                          "it); wait for it to end, then run this again") from None
    except OSError:  # ENOLCK: a network filesystem without locks
        os.close(fd)
        return
    _reading.append(fd)


def hold(directory: Optional[Path], what: str) -> None:
    """Hold `directory`'s lock exclusive until the entry point ends (`releasing` / `release_reads`), or refuse in one
    line naming its holder: a command that rewrites a run's own files (records) while no run trains there and no
    reader reads it. None (a file outside any run dir): nothing to hold."""
    if directory is None or not Path(directory).is_dir():
        return
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise ConfigError(f"{directory} is in use by {holder(directory)}; {what} only while no run trains there and "
                          "nothing reads it: wait for it to end, then run this again") from None
    except OSError:  # ENOLCK: a network filesystem without locks
        os.close(fd)
        return
    _reading.append(fd)


def _mine(directory: Path) -> bool:
    """This process holds the dir's lock (its every holder in /proc/locks is this pid)."""
    try:
        st = os.stat(directory)
        dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
        pids = {line.split()[-4] for line in Path("/proc/locks").read_text().splitlines()
                if "FLOCK" in line and "->" not in line and line.split()[-3] == dev}
        return pids == {str(os.getpid())}
    except (OSError, IndexError):
        return False


def release_reads() -> None:
    while _reading:
        os.close(_reading.pop())


def releasing(main):
    """An entry point's main that reads run dirs: its shared locks go when it returns or fails."""
    @functools.wraps(main)
    def wrapped(*args, **kwargs):
        try:
            return main(*args, **kwargs)
        finally:
            release_reads()
    return wrapped
