"""Where an output really lands and whether a file there is still the one the app wrote (rundir.py asks).

- A path is a path: an output is compared with run dirs by where it really is, each symlink on the way
  followed and each `..` taken after it (`walk`), never by how it is spelled: `out=<run>/../<run>/eval`,
  the dir relative or absolute, or reached through a symlink, all land in that run. The run that holds a
  path is the nearest dir above it with a manifest (`holder`): `out=<another run>/eval` is that run's
  `eval/`, and its manifest answers for it.
- A file is the app's only if the app wrote it: evaluate, export and report record the sha256 of what they
  write when they write it (`digest`); a file whose bytes are no longer those is not replaced.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import List, Optional, Tuple

MANIFEST = ".ppo_torchrl.json"


def walk(path: Path) -> Tuple[Path, List[Tuple[Path, Path]]]:
    """(where `path` really is, [(a symlink on the way, the real dir it sits in)]). A part that does not exist
    yet is taken as written; `..` goes up from where the path really is at that point, as the OS does."""
    spelled = Path(path).expanduser().absolute()
    real, links = Path(spelled.anchor), []
    for part in spelled.parts[1:]:
        if part == "..":
            real = real.parent
            continue
        step = real / part
        if step.is_symlink():
            links.append((step, real))
            try:
                step = step.resolve()
            except (OSError, RuntimeError):  # a loop of links: no file is written through it (the caller refuses)
                pass
        real = step
    return real, links


def holder(path: Path) -> Optional[Path]:
    """The run dir (really, resolved) whose manifest answers for the file `path`: the nearest dir above it
    that has one; None outside any."""
    real, _ = walk(path)
    return next((d for d in real.parents if (d / MANIFEST).is_file()), None)


def inside_run(directory: Path) -> bool:
    """`directory` (a real path) is a run dir or inside one."""
    directory = Path(directory)
    return any((d / MANIFEST).is_file() for d in (directory, *directory.parents))


def digest(path: Path) -> Optional[str]:
    """The sha256 of the file's bytes; None when it cannot be read."""
    sha = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                sha.update(block)
    except OSError:
        return None
    return sha.hexdigest()


def relative(run: Path, real: Path) -> Optional[str]:
    """`real`'s name in `run`'s manifest ('/'-separated), or None when it is not inside it."""
    try:
        return real.relative_to(run).as_posix()
    except ValueError:
        return None

