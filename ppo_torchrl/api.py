"""The Python API: the few calls a script needs (SB3's `learn` / `predict` / `evaluate_policy`), over the same parts
the command line uses (compose and validate the config, claim the run dir, train, load a checkpoint).

    import ppo_torchrl

    run = ppo_torchrl.train(["env=InvertedPendulum-v4", "collector.total_frames=20000"], run_dir="outputs/api_demo")
    policy = ppo_torchrl.load(run.dir)             # the run's best checkpoint, its normalization frozen in
    action = policy.predict(observation)           # a raw Gymnasium observation in, the deterministic action out
    result = ppo_torchrl.evaluate_run(run.dir, episodes=5)
    print(run.summary["eval_return_mean"], result["return_mean"])

`train` takes the command line's overrides (a list of `key=value` strings, as `python -m ppo_torchrl` takes them),
refuses a bad one with `ConfigError` (one line, the same as the CLI's) before it writes anything, and returns
the finished `Run`. `train(resume=<run dir>)` continues a stopped run, `overwrite=True` moves an old run in
`run_dir` aside as the CLI's `overwrite=true` does. `load` and `evaluate_run` read a run dir (`checkpoint=` as the
CLI's: best, last or a file) and write nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Optional, Union

import numpy as np
import torch

PathLike = Union[str, Path]


@dataclass(frozen=True)
class Run:
    """A finished (or stopped) run: its dir and its `summary.json` figures."""

    dir: Path
    summary: dict

    @property
    def status(self) -> str:
        return self.summary.get("status", "")


class Policy:
    """A trained policy with its frozen observation normalization: `predict(obs)` is the action `evaluate` takes."""

    def __init__(self, module: torch.nn.Module, config, frames: int, checkpoint: Path):
        self.module = module
        self.config = config
        self.frames = frames
        self.checkpoint = checkpoint

    @torch.no_grad()
    def predict(self, observation) -> np.ndarray:
        """The deterministic action for a raw observation ([obs_dim] or a batch [..., obs_dim]), within the
        env's action bounds, as a float32 numpy array of the same batch shape."""
        obs = torch.as_tensor(np.asarray(observation), dtype=torch.float64)
        return self.module(obs).numpy()

    def __call__(self, observation) -> np.ndarray:
        return self.predict(observation)


def train(overrides: Iterable[str] = (), *, run_dir: Optional[PathLike] = None, overwrite: bool = False,
          resume: Optional[PathLike] = None) -> Run:
    """Train PPO from command-line overrides (e.g. ["env=Hopper-v4", "seed=3"]); returns the run when it ends.
    run_dir: where (default: the CLI's outputs/<env>/<time>); resume: a stopped run's dir to continue (overrides
    then change what the CLI's resume allows, e.g. collector.total_frames)."""
    from ppo_torchrl.compose import compose, hydra_value
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.lifecycle import Lifecycle
    from ppo_torchrl.trainer import Trainer

    overrides = [str(o) for o in overrides]
    if any(o.startswith(("resume=", "hydra.run.dir=", "overwrite=")) for o in overrides):
        raise ConfigError("train(): give resume, run_dir and overwrite as arguments, not as overrides")
    life = Lifecycle()  # the CLI's lifecycle: the same checks, claims and rollback
    try:
        if resume is not None:
            start = life.resume(str(resume), overrides)
        else:
            cfg = compose(overrides)
            life.check(cfg, keep_env=True)
            directory = Path(run_dir) if run_dir is not None else Path(hydra_value(compose(overrides, with_hydra=True),
                                                                                    "hydra.run.dir"))
            start = life.new_run(directory, overwrite)
            start.cfg = cfg
        summary = Trainer(start.cfg, start.run_dir, start.state, life.env_spec(start.cfg.env), life).train()
    finally:
        life.finish()  # refused before training started: the dir as it was (a started run is kept); locks let go
    return Run(start.run_dir, summary)


def load(run_dir: PathLike, checkpoint: str = "best") -> Policy:
    """A run's policy (checkpoint: best, last or a checkpoint file), ready to `predict`."""
    from ppo_torchrl.checkpoint import load_policy, resolve_checkpoint
    from ppo_torchrl.export import deployed_policy

    run_dir = Path(run_dir)
    path = resolve_checkpoint(run_dir, checkpoint)
    cfg, ac, state = load_policy(run_dir, str(path))
    return Policy(deployed_policy(cfg, ac, state["normalization"]["obs"]), cfg, int(state["frames"]), path)


def evaluate_run(run_dir: PathLike, episodes: int = 10, seed: int = 0, checkpoint: str = "best",
             deterministic: bool = True) -> dict:
    """The eval's figures (return_mean, return_std, per-episode returns and lengths, ...) over `episodes`
    episodes from episode seeds seed * 1000 + i, as `python -m ppo_torchrl.evaluate` computes them; writes nothing."""
    from ppo_torchrl.checkpoint import load_policy, resolve_checkpoint
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.evaluate import evaluate_policy

    if int(episodes) < 1:
        raise ConfigError(f"evaluate_run(): episodes={episodes} must be >= 1")
    run_dir = Path(run_dir)
    cfg, ac, state = load_policy(run_dir, str(resolve_checkpoint(run_dir, checkpoint)))
    return evaluate_policy(cfg, ac, state["normalization"]["obs"], int(episodes), int(seed), deterministic,
                           progress=False)
