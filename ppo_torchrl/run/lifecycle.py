"""A run dir's life, in one place: new, refused, resumed, extended, finished, overwritten (the old run moved
aside and named), initialised from another run, a sweep's job, a trial's seed.

An entry point holds one `Lifecycle` for its command (`python -m ppo_torchrl`: __main__.cli; a script:
api.train) and hands it to the trainer; a sweep's job (which a launcher may run in another process) holds
its own. What a command claimed, holds and may undo lives in that object, never in a module: the locks it
took, the dirs it may roll back, the run it resumes (its checkpoint, read once), the env it built to check
the command (the training env's first, so that a run builds its env once before step 1), the sweep dir
and its Optuna study.

The files themselves (the manifest, what is the app's, atomic writes) are rundir.py's; the rules a claim
applies are written there, in its module doc. A resume is this module (the dir, the checkpoint, the
config it continues with, the frames it has left) and the trainer's `_restore` (its parts' state).
"""

from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional

from omegaconf import OmegaConf

from ppo_torchrl.run import rundir
from ppo_torchrl.errors import ConfigError, EnvironmentFault
from ppo_torchrl.run.locks import holder
from ppo_torchrl.run.ownership import MANIFEST


@dataclass
class Start:
    """What a run starts from: its dir; for a resume, the config it continues with and its checkpoint."""

    run_dir: Path
    cfg: Any = None
    state: Optional[dict] = None


class Lifecycle:
    """One command's claims on run dirs (see rundir.py for the rules): lock, claim, commit, roll back."""

    def __init__(self):
        self._held: Dict[Path, int] = {}  # dir -> the open descriptor that holds its lock
        self._pending: Dict[Path, dict] = {}  # claimed dirs not yet committed: what rollback() undoes
        self._checked = None  # (env config, EnvSpec with its env) of the command's check: the training env's first
        self.start: Optional[Start] = None  # the single run this command claimed before Hydra started
        self.sweep_dir: Optional[Path] = None  # the sweep dir this command claimed
        self.study: Optional[dict] = None  # {storage, study_name}: the Optuna study a sweep runs
        self.overrides: List[str] = []  # the command's key=value overrides where Hydra does not run (the API's train)

    # ------------------------------------------------------------ the command's steps
    def check(self, cfg, keep_env: bool = False):
        """Validate a composed config (validation.py); keep_env: the env built for it is the training env's first."""
        from ppo_torchrl.validation import validate_config

        spec = validate_config(cfg, keep_env=keep_env)
        if keep_env:
            self.env_spec()  # an earlier kept env is closed: one at a time
            self._checked = (cfg.env, spec)
        return spec

    def env_spec(self, env_cfg=None):
        """The spec the command's check built for `env_cfg` (its env handed over once), else None."""
        checked, self._checked = self._checked, None
        if checked is None:
            return None
        if env_cfg is not None and checked[0] == env_cfg:
            return checked[1]
        checked[1].close()
        return None

    def new_run(self, run_dir: Path, overwrite: bool = False) -> Start:
        self.start = Start(Path(self.claim(run_dir, overwrite=overwrite)))
        return self.start

    def sweep(self, sweep_dir: Path, overwrite: bool = False) -> Path:
        self.sweep_dir = Path(self.claim(sweep_dir, overwrite=overwrite, what="sweep"))
        return self.sweep_dir

    def resume(self, resume: str, overrides: List[str]) -> Start:
        """`resume=<dir>`: a run dir with a checkpoint and frames left to train (or a run to finish), on the
        robot model it trained on; else one line that says what to run (the sibling an overwrite moved it to,
        init_from= for a shipped zoo policy, the seed of a trial to resume). The dir is claimed, the
        checkpoint read once."""
        from ppo_torchrl.run import checkpoint
        from ppo_torchrl.run.model_record import check_model

        run_dir = Path(resume).expanduser()
        aside = rundir.moved_aside(run_dir)  # a kill (or a full disk) as an overwrite began leaves its old run there
        moved = f"; overwrite=true moved the run that was there to {aside}: resume={aside}" if aside else ""
        if not run_dir.is_dir():
            raise ConfigError(f"resume={run_dir}: no such directory{moved or '; give the run dir of an earlier run'}")
        if rundir.shipped(run_dir):
            raise ConfigError(f"resume={run_dir}: a shipped zoo policy is read-only; train on from it in a dir of your "
                              f"own with init_from={run_dir}")
        if not rundir.last_checkpoint(run_dir).is_file():
            stopped = [d for d in sorted(run_dir.glob("seed*")) if rundir.is_run(d) and unfinished(d)]
            if (run_dir / "trial.json").is_file() or stopped:  # a trial_seeds run: its seeds are runs of their own
                resumable = [d for d in stopped if rundir.last_checkpoint(d).is_file()]
                then = (f"resume={resumable[0]} continues its stopped seed" if resumable else
                        f"its {stopped[0].name} stopped before its first checkpoint (nothing to resume)" if stopped
                        else "its seeds are all finished")
                again = ("the sweep's command with overwrite=true runs the study on (the stopped trial counts as "
                         "failed)" if rundir.is_run(run_dir.parent) else "overwrite=true starts the "
                         "trial again")
                raise ConfigError(f"resume={run_dir} is a trial of several seeds (trial.json), each seed a run of its "
                                  f"own: {then}; {again}")
            raise ConfigError(f"resume={run_dir} is not a ppo_torchrl run dir with a checkpoint: it needs "
                              f"{rundir.CHECKPOINTS}/{rundir.LAST}{moved}")
        state = checkpoint.load(rundir.last_checkpoint(run_dir))
        if "optimizer" not in state:  # records.record_checkpoint: a reported row's, kept light
            raise ConfigError(f"resume={run_dir}: its last.pt is a record checkpoint (no optimizer state); train on "
                              f"from it with init_from={run_dir} in a dir of your own")
        cfg = resume_config(run_dir, [o for o in overrides if not o.startswith("resume=")], state, announce=True)
        self.check(cfg, keep_env=True)
        check_model(state, cfg.env, f"resume={run_dir}")  # the robot model it trained on, unchanged
        check_frames_left(run_dir, state["frames"], cfg.collector.total_frames, state)
        self.claim(run_dir, resume=True)
        self.start = Start(run_dir, cfg, state)
        return self.start

    # ------------------------------------------------------------ claims
    def lock(self, directory: Path) -> None:
        """Take the dir's lock for this command, or fail naming the process that holds it."""
        directory = Path(directory).resolve()
        if directory in self._held:
            return
        try:
            directory.mkdir(parents=True, exist_ok=True)
            fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
        except OSError as exc:
            raise ConfigError(f"cannot write the run dir {directory}: {exc.strerror or exc}; "
                              "pick a dir you can write with hydra.run.dir=<dir>") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ConfigError(f"{directory} is in use by {holder(directory)}; wait for it to end or pick another "
                              "dir") from None
        except OSError as exc:  # e.g. ENOLCK on a network filesystem without locks
            os.close(fd)
            raise EnvironmentFault(f"cannot lock the run dir {directory}: {exc.strerror or exc} (this filesystem has "
                                   "no file locks); put runs on a local disk with hydra.run.dir=<dir>") from None
        self._held[directory] = fd

    def release(self, directory: Path) -> None:
        fd = self._held.pop(Path(directory).resolve(), None)
        if fd is not None:
            os.close(fd)

    def claim(self, directory: Path, *, overwrite: bool = False, resume: bool = False, what: str = "run") -> Path:
        """Check the dir (rundir.check_new_dir) and lock it; with overwrite, move the old run aside (one rename).
        what="job": a sweep's job dir, checked with its sweep dir; what Hydra wrote there is the job's own."""
        directory = Path(directory).expanduser()
        if directory.resolve() in self._held:  # claimed already by this command (before Hydra started)
            return directory
        created = rundir.missing_parents(directory)
        if directory.is_dir():  # in use by another process: say that first, whatever the dir holds
            self.lock(directory)
        try:
            if not resume and what != "job":
                rundir.check_new_dir(directory, overwrite, what)
        except ConfigError:
            self.release(directory)
            raise
        aside, earlier = None, None
        if overwrite and not resume and what != "job" and directory.is_dir() and rundir.holds_files(directory):
            aside = self._move_aside(directory)
        elif not resume and what != "job":  # empty, or left by a command stopped as it began: name an old run
            earlier = rundir.moved_aside(directory)
        self.lock(directory)
        if resume:
            return directory
        before = set() if what == "job" else set(rundir.files_in(directory))
        state = {"what": what, "created": created, "aside": aside, "before": before, "manifest": False,
                 "earlier": earlier}
        self._pending[directory.resolve()] = state
        if aside is not None and what == "sweep":  # its commit comes at the sweep's end: a kill during a job
            state["said"] = True                   # would leave the sibling unnamed, so it is named now
            print(f"overwrite=true: the sweep that was in {directory} is now {aside} (delete it when you no longer "
                  "need it; it goes back if no job starts)", file=sys.stderr, flush=True)
        if not (directory / MANIFEST).exists():  # the dir is the app's from its first file: a kill during start-up
            try:                                 # leaves a run dir
                files = [] if what == "sweep" else list(rundir.STARTED)  # write-ahead (rundir.STARTED)
                rundir.atomic_write_json(directory / MANIFEST, {"app": "ppo_torchrl", "files": files})
            except BaseException:  # a full disk, a signal: the old run back in its dir, nothing of this command left
                self.rollback(directory)
                raise
            state["manifest"] = True
        return directory

    def _move_aside(self, directory: Path) -> Path:
        """Rename `directory` to a new sibling <name>.replaced-<time>, once every run dir inside it is locked
        by this command (one in use by another refuses, naming it); the locks go with the moved dirs."""
        inner = [Path(root) for root, _, files in os.walk(directory) if MANIFEST in files and Path(root) != directory]
        try:
            for run in inner:
                self.lock(run)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            aside = directory.with_name(f"{directory.name}{rundir.ASIDE}{stamp}")
            n = 1
            while aside.exists():
                n += 1
                aside = directory.with_name(f"{directory.name}{rundir.ASIDE}{stamp}-{n}")
            os.rename(directory, aside)
        finally:
            for run in inner:
                self.release(run)
            self.release(directory)
        return aside

    def source(self, path: Path) -> Path:
        """Where `path` is now: a path into a dir whose old run overwrite=true moved aside (init_from=<that run>)
        reads the moved files."""
        path = Path(path).expanduser().resolve()
        for key, state in self._pending.items():
            if state["aside"] and (path == key or key in path.parents):
                return state["aside"].resolve() / path.relative_to(key)
        return path

    def commit(self, directory: Path) -> None:
        """The new run has started: it keeps its dir (the run it replaced stays where overwrite moved it, named
        here); list its own files, first: a signal or a full disk before they are listed leaves the claim pending,
        which rollback() undoes (its files are never left unlisted, for the user's)."""
        directory = Path(directory)
        rundir.record(directory)
        state = self._pending.pop(directory.resolve(), None)
        if state is not None and state["aside"] and not state.get("said"):
            print(f"overwrite=true: the {state['what']} that was in {directory} is now {state['aside']} (delete it "
                  "when you no longer need it)", file=sys.stderr, flush=True)
        elif state is not None and state["earlier"]:  # e.g. a kill as an overwrite began: its old run, named
            print(f"note: {state['earlier']} holds the {state['what']} an earlier overwrite=true moved out of "
                  f"{directory} (delete it when you no longer need it)", file=sys.stderr, flush=True)

    def rollback(self, directory: Optional[Path] = None) -> None:
        """A claimed dir whose command failed before `commit`: remove what it wrote, put back what it moved aside."""
        for key in ([Path(directory).resolve()] if directory is not None else list(self._pending)):
            state = self._pending.pop(key, None)
            if state is None:
                continue
            self.release(key)
            try:
                for name in rundir.files_in(key):
                    if name not in state["before"]:
                        (key / name).unlink()
                if state["manifest"]:
                    (key / MANIFEST).unlink()
                rundir.prune_empty(key)
                if state["aside"]:
                    key.rmdir()  # only this command's (now empty) dir: the old run goes back in one rename
                    os.rename(state["aside"], key)
                for path in state["created"]:
                    path.rmdir()
            except (OSError, ConfigError):
                pass  # best effort: what is left is named by the next claim's check (the old run stays whole)

    def finish(self) -> None:
        """At the end of a command: a sweep dir whose jobs started is committed; anything else still pending
        (a run or sweep refused before it started) is rolled back; every lock let go, the kept env closed."""
        for key, state in list(self._pending.items()):
            if state["what"] == "sweep" and any(rundir.is_run(job) for job in rundir.job_dirs(key)):
                self.commit(key)
            else:
                self.rollback(key)
        for directory in list(self._held):
            self.release(directory)
        self.env_spec()


def resume_config(run_dir, overrides, state: dict, announce: bool = False):
    """The checkpoint's config of `run_dir` (config.run_config) with this command's `key=value` overrides applied
    on top. A group choice (`logger=csv`) is accepted when it is the run's own (`.hydra/hydra.yaml`), refused
    otherwise."""
    from ppo_torchrl.config import run_config
    from ppo_torchrl.config_data import read_yaml

    cfg = run_config(run_dir, state, announce)
    hydra_file = Path(run_dir) / ".hydra" / "hydra.yaml"
    try:
        choices = read_yaml(hydra_file, ("hydra", "runtime", "choices")) if hydra_file.is_file() else {}
    except Exception:  # noqa: BLE001 - a damaged hydra.yaml (or not data): group choices cannot be compared, none is accepted
        choices = {}
    for override in overrides:
        group, _, option = override.partition("=")
        if group in choices:
            saved_choice = "null" if choices[group] is None else choices[group]
            if option != saved_choice:
                raise ConfigError(f"resume: {override} differs from the run's {group}={saved_choice}; a resumed "
                                  "run keeps its group choices (only key=value overrides apply)")
            continue
        try:
            cfg = OmegaConf.merge(cfg, OmegaConf.from_dotlist([override]))
        except Exception as exc:
            from ppo_torchrl.overrides import key_hint  # a misspelt key: the closest one

            raise ConfigError(
                f"resume: cannot apply '{override}' to the saved config ({str(exc).splitlines()[0]}); "
                "on resume only key=value overrides of existing keys apply, e.g. collector.total_frames=N"
                f"{key_hint(group, cfg)}") from exc
    cfg.resume = str(run_dir)
    return cfg


def check_frames_left(run_dir, frames_done: int, total_frames: int, state: dict = None) -> None:
    """A resume must leave frames to train (a smaller total would be a silent no-op), or a run to finish: one that
    has trained its own budget (the checkpoint's) and was stopped before its end (`unfinished`)."""
    own = (((state or {}).get("config") or {}).get("collector") or {}).get("total_frames")
    if frames_done >= total_frames and not (own is not None and frames_done >= own and unfinished(run_dir)):
        raise ConfigError(f"resume={run_dir}: the run has done {frames_done} frames already, collector.total_frames="
                          f"{total_frames} leaves nothing to do; give a larger collector.total_frames")


def unfinished(run_dir) -> bool:
    """The run's summary.json does not say `finished` (none, unreadable, interrupted, failed): a run stopped
    after its last batch (its final eval skipped or cut, a kill before its last summary) that resume= finishes."""
    try:
        return json.loads((Path(run_dir) / "summary.json").read_text()).get("status") != "finished"
    except (OSError, ValueError, AttributeError):
        return True
