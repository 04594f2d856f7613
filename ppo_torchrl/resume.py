"""`resume=<run dir>`: the command is checked before Hydra starts (__main__.prepare): a dir that is a run
with a checkpoint and frames left to train, else one line that says what to run (the sibling an
overwrite moved it to, init_from= for a shipped zoo policy, the seed of a trial to resume).
"""

from __future__ import annotations

import glob
from pathlib import Path

from ppo_torchrl.errors import ConfigError


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError):
        return ""


def check_resume(resume: str, overrides: list[str]) -> Path:
    """`resume=<dir>` must be a run dir with a checkpoint that has frames left to train."""
    from ppo_torchrl import checkpoint
    from ppo_torchrl.config import resume_config
    from ppo_torchrl.model_record import check_model
    from ppo_torchrl.rundir import ASIDE, shipped
    from ppo_torchrl.validation import check_frames_left, validate_config

    run_dir = Path(resume).expanduser()
    if not run_dir.is_dir():
        moved = sorted(run_dir.parent.glob(f"{glob.escape(run_dir.name)}{ASIDE}*")) if run_dir.parent.is_dir() else []
        hint = (f"; overwrite=true moved the run that was there to {moved[-1]}: resume={moved[-1]}" if moved
                else "; give the run dir of an earlier run")
        raise ConfigError(f"resume={run_dir}: no such directory{hint}")
    if shipped(run_dir):
        raise ConfigError(f"resume={run_dir}: a shipped zoo policy is read-only; train on from it in a dir of your own "
                          f"with init_from={run_dir}")
    if not (run_dir / "checkpoints" / "last.pt").is_file():
        stopped = [d for d in sorted(run_dir.glob("seed*")) if (d / "checkpoints" / "last.pt").is_file()
                   and '"status": "finished"' not in _read(d / "summary.json")]
        if (run_dir / "trial.json").is_file() or stopped:  # a trial_seeds run: its seeds are runs of their own
            then = (f"resume={stopped[0]} continues its stopped seed" if stopped else "its seeds are all finished")
            raise ConfigError(f"resume={run_dir} is a trial of several seeds (trial.json), each seed a run of its own: "
                              f"{then}; overwrite=true starts the trial again")
        raise ConfigError(f"resume={run_dir} is not a ppo_torchrl run dir with a checkpoint: it needs "
                          "checkpoints/last.pt")
    state = checkpoint.load(run_dir / "checkpoints" / checkpoint.LAST)
    cfg = resume_config(run_dir, [o for o in overrides if not o.startswith("resume=")], state, announce=True)
    validate_config(cfg)
    check_model(state, cfg.env, f"resume={run_dir}")  # the robot model it trained on, unchanged
    check_frames_left(run_dir, state["frames"], cfg.collector.total_frames, state)
    return run_dir
