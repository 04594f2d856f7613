"""Run dirs are owned: one run per dir, one process per dir at a time, and only the app's files touched.

- Each run dir holds a manifest (`.ppo_torchrl.json`) of the files this app wrote there (`record`); what
  evaluate, export and report write is listed with the sha256 of its bytes, and replaced only while it holds
  them. An output belongs to the run dir that really holds it, however its path is spelled (ownership.py).
  A dir is a run dir only when it has one and every file in it is listed (or is a checkpoint or
  temporary file of a write killed before it was listed), with no symlink anywhere. A claim lists the
  files a run writes before its first listing (STARTED) when it makes the manifest: write-ahead, so a
  kill or a full disk between such a write and the listing leaves a file the manifest calls the app's.
- A new run needs a dir that does not exist or is empty. A run dir is refused unless
  `overwrite=true`; a dir holding anything else is always refused (it is somebody's files).
- `overwrite=true` deletes nothing: it checks the whole dir, takes the lock of every run dir in it
  (a sweep's jobs, a trial's seeds: one in use refuses the command, naming its process), then moves
  the old run aside in one rename, to a sibling `<dir>.replaced-<time>` that the start of the new
  run names (deleting it is the user's act). A command refused after that (a bad `init_from`, a
  Ctrl-C during start-up) removes what it wrote and renames the old run back (`rollback`). A kill
  at any instant leaves the old run whole, in its dir or in the sibling.
- `resume=<dir>` continues the run in its own dir.
- A lock on the dir itself (`flock` of its file descriptor: released even by kill -9, no file
  written) stops a second process from writing into a dir in use; the refusal names the holder. It is
  exclusive; evaluate, export and report hold it shared while they read the dir (locks.py).

These are the rules; lifecycle.py applies them (a command's claims, locks and rollbacks: `Lifecycle.claim()`
runs before Hydra or the app writes anything, so a refused command changes nothing).
"""

from __future__ import annotations

import errno
import fcntl
import glob
import json
import os
import re
import tempfile
import time
from pathlib import Path
from typing import Dict, List, Optional

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.ownership import MANIFEST, digest, holder, inside_run, relative, walk

CHECKPOINTS = "checkpoints"  # a run dir's checkpoint folder
LAST = "last.pt"  # in it, the checkpoint a resume continues from


def last_checkpoint(run_dir: Path) -> Path:
    """The checkpoint `resume=<run_dir>` continues from."""
    return Path(run_dir) / CHECKPOINTS / LAST

STASH = ".replaced"  # earlier versions moved an overwritten run's files here; one left by a kill is moved aside whole
ASIDE = ".replaced-"  # overwrite=true: <dir>.replaced-<time> holds the run it replaced
LEGACY_LOCK = ".lock"  # earlier versions locked a file of this name; a leftover one is ours
# The temp file of a manifest write cut short (a kill as a claim began, e.g. just after overwrite moved the old run
# aside): the app's, in a dir that holds nothing else a new run may start.
MANIFEST_TMP = re.compile(rf"^\.{re.escape(MANIFEST)}\.[^/]+\.tmp$")
# What the app writes, by place. logs/ is the loggers' (any name). A run or a resume writes TRAIN_FILES, which
# `record` lists by name and time; evaluate, export and report list the files they write as they write them.
TRAIN_FILES = (r"config\.yaml|metrics\.csv|summary\.json|error\.log|__main__\.log"
               r"|\.hydra/(?:config|hydra|overrides)\.yaml|checkpoints/(?:last|best|frames_\d+)\.pt"
               r"|videos/[^/]+\.mp4|logs/.+")
RUN_FILES = rf"{TRAIN_FILES}|report\.png|policy\.pt|eval/[^/]+\.(?:json|csv|png|mp4)"
# A run with trial_seeds is the parent of one run dir per seed (seed<k>/, each with its own manifest).
OWNED = re.compile(rf"^(?:{RUN_FILES}|multirun\.yaml|optimization_results\.yaml|sweep_report\.(?:png|md|csv)|\.lock"
                   rf"|trial\.json|seed\d+/(?:{RUN_FILES}|{re.escape(MANIFEST)}))$")
TRAINED = re.compile(rf"^(?:{TRAIN_FILES}|multirun\.yaml|optimization_results\.yaml|trial\.json"
                     rf"|seed\d+/(?:{TRAIN_FILES}|{re.escape(MANIFEST)}))$")  # what `record` lists by name and time
# Listed or not, these are the app's in an app's dir: a checkpoint or a temp file of a write cut short.
# (Hydra's start-up files too, a sweep's multirun.yaml: a command killed before it listed them; nothing is ever
# deleted for being here)
UNLISTED_OK = re.compile(r"^(?:(?:seed\d+/)?checkpoints/(?:last|best|frames_\d+)\.pt|(?:.+/)?\.[^/]+\.tmp"
                         r"|\.hydra/(?:config|hydra|overrides)\.yaml|__main__\.log"
                         r"|multirun\.yaml|optimization_results\.yaml)$")  # Hydra's: a sweep killed before it listed them

# The files a run (a trial: trial.json) may write before its first `record`: listed by name, no sha256, in the
# manifest its claim makes (Lifecycle.claim); `record` drops a name whose file never came.
STARTED = ("config.yaml", "metrics.csv", "summary.json", "error.log", "trial.json")

ZOO = Path(__file__).resolve().parents[2] / "zoo"  # the shipped policies: read-only to every command
_BEGAN_NS = time.time_ns()  # this process's start: `record` lists only the files written since


def files_in(directory: Path) -> List[str]:
    """Every file under `directory` (relative, '/'-separated), the manifest and the stash left out.
    A symlink anywhere is refused: the app never writes one, and following it could delete elsewhere."""
    found = []
    for root, dirs, files in os.walk(directory):
        rel_root = Path(root).relative_to(directory)
        if rel_root == Path("."):
            dirs[:] = [d for d in dirs if d != STASH]
        for name in dirs + files:
            if os.path.islink(os.path.join(root, name)):
                raise ConfigError(f"{directory} holds a symlink, {Path(root) / name}, which this app never writes; "
                                  "it leaves such a dir alone: pick another dir, or remove the link yourself")
        found += [(rel_root / name).as_posix() for name in files if not (rel_root == Path(".") and name == MANIFEST)]
    return sorted(found)


def atomic_write_bytes(path: Path, write, owner: Optional[Path] = None) -> None:
    """Call write(file) on a temp file in path's folder, fsync it, then rename it onto path. An OSError
    (a full disk, no permission) names `path`, so the one error line says where.
    owner: the run dir an output of evaluate, export or report goes to: `path` is listed in its manifest
    between the whole temp file and the rename (`intend`), so a failure before changes nothing and a kill
    at any instant leaves the old file or the new one, the app's either way."""
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)  # mkstemp makes files private; these are ordinary outputs
        if owner is not None:
            intend(owner, [path], {path: digest(tmp)})
        os.replace(tmp, path)
    except BaseException as exc:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not exc.filename:
            raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def atomic_write_json(path: Path, data: dict, owner: Optional[Path] = None) -> None:
    atomic_write_bytes(path, lambda f: f.write((json.dumps(data, indent=2, default=float) + "\n").encode()), owner)


def listed(directory: Path) -> Optional[List[str]]:
    """The manifest's files, or None when the dir has no (readable) manifest."""
    try:
        data = json.loads((Path(directory) / MANIFEST).read_text())
        files = data["files"]
        if not isinstance(files, list):
            return None
        return [f for f in files if isinstance(f, str)]  # an edited manifest's other entries name nothing
    except (OSError, ValueError, KeyError, TypeError):
        return None


def digests(directory: Path) -> Dict[str, List[str]]:
    """The manifest's record of what evaluate, export and report wrote: name -> the sha256 of the bytes they
    wrote (two while a write is under way: the old file's and the new one's). A listed name without one is
    the app's whatever it holds (a manifest of an earlier version, a video being written)."""
    try:
        data = json.loads((Path(directory) / MANIFEST).read_text())["sha256"]
        return {k: [h for h in v if isinstance(h, str)] for k, v in data.items() if isinstance(v, list)}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _write_manifest(directory: Path, files, known: Dict[str, List[str]]) -> None:
    files = sorted(set(files))
    atomic_write_json(Path(directory) / MANIFEST, {"app": "ppo_torchrl", "files": files,
                                                   "sha256": {f: known[f] for f in files if known.get(f)}})


def _by_run(paths: List[Path]) -> Dict[Path, Dict[str, Path]]:
    """The given outputs by the run dir that really holds each (ownership.holder): run -> {name: path}. Outputs
    outside any run dir, or in a shipped one, are left out."""
    runs: Dict[Path, Dict[str, Path]] = {}
    for path in paths:
        path = Path(path)
        real, _ = walk(path)
        run = holder(path)
        name = relative(run, real) if run is not None else None
        if name is not None and not shipped(run) and _inside(run, name):
            runs.setdefault(run, {})[name] = path
    return runs


def record(directory: Path, files: Optional[List[Path]] = None) -> None:
    """Add to the manifest the files this command wrote: `files` (the paths evaluate, export or report just
    wrote; each listed in the run dir that holds it, with the sha256 of the bytes it holds now), or without
    them the files of the kinds a run or a resume writes (TRAINED) in `directory`, written since this process
    began and not later than now (the trainer, Hydra and the loggers write there). A file that was there
    before the command, a user's, is never listed by it; nor is a file of a kind the run does not write
    (a policy.pt or report.png put there while a resume trains), nor one dated in the future (clock skew,
    `cp -p`, `tar x`)."""
    if files is not None:
        for run, written in _by_run(files).items():
            known = digests(run)
            for name in written:
                now = digest(run / name)
                if now is not None and (name not in known or now in known[name]):
                    known[name] = [now]  # the bytes this command wrote (a user's change since stays refused)
            _write_manifest(run, _kept(run, set(listed(run) or []) | set(written)), known)
        return
    directory = Path(directory)
    if not directory.is_dir():
        return
    listed_now = set(listed(directory) or [])
    until = time.time_ns()
    try:
        listed_now.update(f for f in files_in(directory) if TRAINED.match(f)
                          and _BEGAN_NS <= (directory / f).stat().st_mtime_ns <= until)
    except ConfigError:  # a symlink put there by hand: listed files stay as they were
        pass
    _write_manifest(directory, _kept(directory, listed_now), digests(directory))


def _kept(directory: Path, names) -> List[str]:
    return [f for f in names if isinstance(f, str) and _inside(directory, f) and (Path(directory) / f).is_file()]


def intend(directory: Path, paths: List[Path], written: Optional[Dict[Path, Optional[str]]] = None) -> None:
    """Just before evaluate, export or report write `paths` (every check passed): list them first, in the run
    dir that holds each (write-ahead), with the sha256 of the bytes about to land (`written`: path -> sha256),
    so a kill in the middle of a write leaves a file the manifest calls the app's (the next command replaces
    it), never one that looks like the user's. A path without a sha256 (a video, written in place) is the
    app's whatever it holds until `record` lists what it wrote. A name whose file never came is dropped by
    the next `record`. (`directory`, the run the command is about, is not asked: a path is its holder's.)"""
    for run, names in _by_run(paths).items():
        files, known = set(listed(run) or []), digests(run)
        before = (set(files), {k: list(v) for k, v in known.items()})
        for name, path in names.items():
            new = (written or {}).get(path)
            if name not in files:
                files.add(name)
                if new is not None:
                    known[name] = [new]
            elif new is None:
                known.pop(name, None)
            elif name in known and new not in known[name]:
                known[name] = known[name][-1:] + [new]  # the old bytes or the new: a kill leaves one of them
        if (files, known) != before:
            _write_manifest(run, files, known)


def _inside(directory: Path, name: str) -> bool:
    """A manifest entry names a file inside its dir: relative, no '..', no symlink on the way."""
    path = Path(name)
    if path.is_absolute() or ".." in path.parts:
        return False
    here = Path(directory)
    for part in path.parts:
        here = here / part
        if here.is_symlink():
            return False
    return True


def check_replaceable(directory: Path, paths: List[Path]) -> None:
    """Before evaluate, export or report write `paths`: one ConfigError line for a path that goes through a
    symlink inside a run dir, lands in a shipped zoo folder, or would replace a file of a run dir (the one that
    really holds it, however the path is spelled: ownership.py) that the app did not write there: one its
    manifest does not list, or whose bytes are no longer those the app recorded when it wrote them.
    (`directory`, the run the command is about, is not asked: a path is its holder's.)"""
    for path in paths:
        path = Path(path)
        real, links = walk(path)
        for link, where in links:
            if inside_run(where):
                raise ConfigError(f"{link} is a symlink, which this app never writes through; give another "
                                  "output dir (out=<dir>) or remove the link yourself")
        if shipped(real.parent):
            raise ConfigError(f"{path} is in the shipped zoo/, which every command only reads; give another "
                              "output dir (out=<dir>)")
        run = holder(path)
        if run is None or not (real.exists() or real.is_symlink()):
            continue
        name = relative(run, real)
        what = f"{path}" + (f" (that is {real})" if Path(path).absolute() != real else "")
        if name not in set(listed(run) or []):
            raise ConfigError(f"{what} is not a file this app wrote (the run's {MANIFEST} does not list it); it is "
                              "left as it is: move it, or write elsewhere (out=<dir> for evaluate)")
        accepted = digests(run).get(name)
        if accepted and digest(real) not in accepted:
            raise ConfigError(f"{what} is not a file this app wrote: its bytes changed after the app wrote it (the "
                              f"sha256 in {run / MANIFEST} differs); it is left as it is: move it away, or write "
                              "elsewhere (out=<dir> for evaluate)")


def foreign_files(directory: Path) -> List[str]:
    """The files of `directory` that the app did not write ([] for an app's dir; all of them without a manifest).
    A run dir inside it (a trial's seed<k>/) answers for its own files by its own manifest: a seed stopped
    midway is the app's even before the trial's manifest lists it."""
    files = files_in(directory)
    ours = listed(directory)
    if ours is None:
        return [f for f in files if f != LEGACY_LOCK and not MANIFEST_TMP.match(f)]
    ours = set(ours)
    nested = {}  # a run dir inside (relative) -> its listed files
    for root, _, names in os.walk(directory):
        if MANIFEST in names and Path(root) != Path(directory):
            nested[Path(root).relative_to(directory).as_posix()] = set(listed(root) or [])

    def own(name: str) -> bool:
        if name in ours or UNLISTED_OK.match(name):
            return True
        # the run dir nearest the file answers for it: a trial's seed<k>/ inside a sweep's job, not the job
        for inner in sorted((d for d in nested if name.startswith(d + "/")), key=len, reverse=True)[:1]:
            rest = name[len(inner) + 1:]
            return rest == MANIFEST or rest in nested[inner] or bool(UNLISTED_OK.match(rest))
        return False

    return [f for f in files if not own(f)]


def job_dirs(directory: Path) -> List[Path]:
    return [p for p in sorted(directory.iterdir()) if p.is_dir() and not p.is_symlink() and p.name != STASH]


def holds_files(directory: Path) -> bool:
    """Anything in the dir: a file (the manifest, an old stash and the manifest's temp file a kill left as an
    overwrite began aside: that dir holds no run, and its start names the sibling that does) or a job's folder."""
    return bool([f for f in files_in(directory) if not MANIFEST_TMP.match(f)] or job_dirs(directory))


def is_run(directory: Path) -> bool:
    return (Path(directory) / MANIFEST).is_file()


def check_new_dir(directory: Path, overwrite: bool, what: str = "run") -> None:
    """Refuse a dir that holds a run (or a sweep of runs) unless overwrite; refuse anything else not empty."""
    directory = Path(directory)
    key = "hydra.run.dir" if what == "run" else "hydra.sweep.dir"
    if directory.exists() and not directory.is_dir():
        raise ConfigError(f"the {what} dir {directory} is a file; give {key} a directory")
    if not directory.is_dir():
        return
    if not [f for f in files_in(directory) if f != LEGACY_LOCK and not MANIFEST_TMP.match(f)] and not job_dirs(directory):
        return  # empty (empty folders, a stale lock file of an earlier version): a new run may use it
    if what == "run" or is_run(directory):  # a dir with a manifest (a run's, a trial's, a sweep's) answers by it
        foreign, has_run = foreign_files(directory), is_run(directory)
    else:  # a sweep dir of an earlier version: its own files, and job dirs that are each a run dir (or empty)
        foreign = [f for f in foreign_files(directory) if "/" not in f]
        for job in job_dirs(directory):
            if files_in(job):
                foreign += [f"{job.name}/{f}" for f in foreign_files(job)]
        has_run = is_run(directory) or any(is_run(job) for job in job_dirs(directory))
    legacy = {"metrics.csv", "summary.json", f"{CHECKPOINTS}/{LAST}"} & set(foreign)  # what every run wrote
    if what == "run" and not has_run and legacy and all(OWNED.match(f) for f in foreign):
        raise ConfigError(f"{directory} holds a run of an earlier version, which listed no files: overwrite=true cannot "
                          f"tell its files from yours; continue it with resume={directory}, pick a new dir with "
                          f"{key}=<dir>, or remove it yourself")
    if foreign or not has_run:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise ConfigError(f"{directory} is not empty and is not a ppo_torchrl {what} dir (it holds {shown or 'folders'}, "
                          f"which this app did not write); pick an empty or new dir with {key}=<dir>")
    if not overwrite:
        hint = ""
        if what == "run":  # resume needs a checkpoint: a run killed before its first one has nothing to continue
            hint = (f"continue it with resume={directory}, " if last_checkpoint(directory).is_file()
                    else f"it has no {CHECKPOINTS}/{LAST} (nothing to resume): ")
        raise ConfigError(f"{directory} already holds a {what}: {hint}pick a new dir with {key}=<dir>, "
                          "or replace it with overwrite=true")


def moved_aside(directory: Path) -> Optional[Path]:
    """The newest sibling <dir>.replaced-<time> that overwrite=true moved an old run of `directory` to, or None."""
    directory = Path(directory).expanduser()
    try:
        siblings = [p for p in directory.parent.glob(f"{glob.escape(directory.name)}{ASIDE}*") if p.is_dir()]
    except OSError:
        return None
    return max(siblings, key=lambda p: p.name) if siblings else None


def shipped(directory: Path) -> bool:
    """A folder of the shipped zoo (or inside one): commands read it and write their files elsewhere."""
    path = Path(directory).expanduser().resolve()
    return path == ZOO or ZOO in path.parents


def output_dir_for(directory: Path, default: Path) -> Path:
    """Where a command writes the files it makes for the run in `directory`: `default` (inside the run dir), or for a
    shipped run, one under zoo/ or results/ (the repository's records, which stay as they were shipped), the same
    path under outputs/: outputs/zoo/<name>/, outputs/results/robots/<round>/<run>/ (shipped.shipped_run)."""
    from ppo_torchrl.shipped import shipped_run

    inside = shipped_run(directory)
    return Path("outputs") / inside if inside is not None else default


def in_use(directory: Path) -> bool:
    """Another process (or another claim of this one) writes there: a run still training holds its lock exclusive
    (lifecycle.py); a reader's shared lock, an evaluate's, is not asked. Leaves the lock as it was."""
    directory = Path(directory).resolve()
    try:
        fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return False
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


def missing_parents(directory: Path) -> List[Path]:
    missing, path = [], directory.resolve()
    while not path.exists():
        missing.append(path)
        path = path.parent
    return missing


def prune_empty(directory: Path) -> None:
    """Remove the empty folders under `directory` (bottom up), never `directory` itself."""
    for root, dirs, _ in os.walk(directory, topdown=False):
        for name in dirs:
            path = Path(root) / name
            if not path.is_symlink():
                try:
                    path.rmdir()
                except OSError:
                    pass


def unwritable(path: Path) -> Optional[str]:
    """Why files cannot be written in the folder `path`, or None when they can; leaves the disk as it was."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        return "it is a file"
    created = missing_parents(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".ppo_torchrl_probe_{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        return exc.strerror or errno.errorcode.get(exc.errno, str(exc))
    finally:
        for folder in created:
            try:
                folder.rmdir()
            except OSError:
                pass
    return None
