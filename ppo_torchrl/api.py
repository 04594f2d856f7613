"""The Python API: the few calls a script needs (SB3's `learn` / `predict` / `evaluate_policy`), over the same parts
the command line uses (compose and validate the config, claim the run dir, train, load a checkpoint).

    import ppo_torchrl

    run = ppo_torchrl.train(["env=InvertedPendulum-v4", "collector.total_frames=20000"], run_dir="outputs/api_demo")
    policy = ppo_torchrl.load(run.dir)             # the run's best checkpoint, its normalization frozen in
    action = policy.predict(observation)           # a raw Gymnasium observation in, the deterministic action out
    result = ppo_torchrl.evaluate_run(run.dir, episodes=5)
    print(run.summary["eval_return_mean"], result["return_mean"])

`train` takes the command line's overrides (a list of `key=value` strings, as `python -m ppo_torchrl` takes them),
refuses a bad one with `ConfigError` (one line, the same as the CLI's: the same checks run on every argument, a
misspelt key gets the closest one) before it writes anything, and returns the finished `Run`; a Ctrl-C in training
saves a checkpoint and reaches the caller as KeyboardInterrupt. `train(resume=<run dir>)` continues a stopped run, `overwrite=True` moves an old run in
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
        self.obs_dim = int(module.policy_net[0][0].in_features)

    @torch.no_grad()
    def predict(self, observation) -> np.ndarray:
        """The deterministic action for a raw observation ([obs_dim] or a batch [..., obs_dim]), within the
        env's action bounds, as a float32 numpy array of the same batch shape. An observation of another size (it
        was broadcast against the statistics), not numbers, or not finite (NaN in, NaN actions out) is ConfigError,
        a ValueError, naming what it got."""
        from ppo_torchrl.errors import ConfigError

        try:
            obs = np.asarray(observation, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"predict(): the observation ({type(observation).__name__}) is not an array of numbers; "
                              f"give a float array of shape [{self.obs_dim}] or [..., {self.obs_dim}]") from None
        if obs.ndim == 0 or obs.shape[-1] != self.obs_dim:
            raise ConfigError(f"predict(): an observation of shape {list(obs.shape)} for a policy of observations of "
                              f"size {self.obs_dim}; give [{self.obs_dim}] or a batch [..., {self.obs_dim}]")
        if not np.isfinite(obs).all():
            bad = np.argwhere(~np.isfinite(obs))[0].tolist()
            raise ConfigError(f"predict(): the observation holds {obs[tuple(bad)]} at {bad}: every value must be "
                              "finite (the env diverged, or the observation was not filled in)")
        return self.module(torch.as_tensor(obs)).numpy()

    def __call__(self, observation) -> np.ndarray:
        return self.predict(observation)


def _flag(name: str, value) -> bool:
    """A bool argument as the CLI takes one (true / false), never a string taken as true."""
    from ppo_torchrl.errors import ConfigError

    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{name}={value!r} must be True or False (a bool, not {type(value).__name__})")
    return bool(value)


def _override_list(overrides) -> list:
    from ppo_torchrl.errors import ConfigError

    if isinstance(overrides, (str, bytes)):
        raise ConfigError(f"train(): overrides={overrides!r} is one string; give a list of key=value strings, "
                          f"e.g. [{overrides!r}]")
    given = list(overrides)
    wrong = next((o for o in given if not isinstance(o, str)), None)
    if wrong is not None:
        raise ConfigError(f"train(): the override {wrong!r} is a {type(wrong).__name__}; each is a key=value string, "
                          "e.g. 'seed=3'")
    return given


OWN_ARGUMENTS = {"resume": "resume", "hydra.run.dir": "run_dir", "overwrite": "overwrite"}


def train(overrides: Iterable[str] = (), *, run_dir: Optional[PathLike] = None, overwrite: bool = False,
          resume: Optional[PathLike] = None) -> Run:
    """Train PPO from command-line overrides (e.g. ["env=Hopper-v4", "seed=3"]); returns the run when it ends.
    run_dir: where (default: the CLI's outputs/<env>/<time>); resume: a stopped run's dir to continue, in its own dir
    (overrides then change what the CLI's resume allows, e.g. collector.total_frames).

    Every argument is checked as the CLI checks it (overrides.checked_overrides, the config's validation): a bad one
    is ConfigError before anything is written. Ctrl-C in the training loop saves a checkpoint, as the CLI does, and
    reaches the caller as KeyboardInterrupt (SIGTERM too), never as an Exception a loop over seeds would go on from."""
    from ppo_torchrl.compose import compose, hydra_value
    from ppo_torchrl.errors import ConfigError, Interrupted
    from ppo_torchrl.run.lifecycle import Lifecycle
    from ppo_torchrl.overrides import check_path, checked_overrides, key_of, plain_keys, split_args
    from ppo_torchrl.trainer import Trainer

    overrides = plain_keys(_override_list(overrides))
    flags, overrides = split_args(overrides)  # --env Hopper-v4: one line naming env=Hopper-v4
    if flags:
        raise ConfigError(f"train(): {flags[0]} is a flag of the command line; train() runs one run from key=value "
                          "overrides (a sweep: call it once per job)")
    named = next((o for o in overrides if key_of(o) in OWN_ARGUMENTS), None)
    if named is not None:
        raise ConfigError(f"train(): give resume, run_dir and overwrite as arguments, not as overrides: {named} is "
                          f"train(..., {OWN_ARGUMENTS[key_of(named)]}=...)")
    overwrite = _flag("train(): overwrite", overwrite)
    if resume is not None and (run_dir is not None or overwrite):
        raise ConfigError(f"train(): resume={str(resume)!r} continues that run in its own dir; "
                          + ("run_dir= names a dir for a new run: give one of them, not both" if run_dir is not None
                             else "overwrite=True starts a new run in place of it: give one of them"))
    if run_dir is not None:
        check_path("hydra.run.dir", run_dir, f"train(): run_dir={str(run_dir)!r}",
                   "give run_dir=<dir>, or leave run_dir out (the CLI's outputs/runs/<date>/<time>_<env>_seed<k>/)")
    if resume is not None:
        check_path("resume", resume, f"train(): resume={str(resume)!r}", "give resume=<run dir>, or leave it out")
    overrides = checked_overrides(overrides, compose)  # ++key, ~key, env=, 1e6, paths: as the CLI's prepare
    life = Lifecycle()  # the CLI's lifecycle: the same checks, claims and rollback
    life.overrides = overrides  # the start line credits these to the user, not to the env file
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
    except Interrupted as stop:  # the checkpoint is saved (its line says where): the caller's Ctrl-C
        raise KeyboardInterrupt(f"interrupted: {stop}") from stop
    finally:
        life.finish()  # refused before training started: the dir as it was (a started run is kept); locks let go
    return Run(start.run_dir, summary)


def load(run_dir: PathLike, checkpoint: str = "best") -> Policy:
    """A run's policy (checkpoint: best, last or a checkpoint file), ready to `predict`."""
    from ppo_torchrl.run.checkpoint import load_policy, resolve_checkpoint
    from ppo_torchrl.export import deployed_policy

    run_dir = _run_dir("load", run_dir)
    path = resolve_checkpoint(run_dir, _checkpoint("load", checkpoint))
    cfg, ac, state = load_policy(run_dir, str(path))
    return Policy(deployed_policy(cfg, ac, state["normalization"]["obs"]), cfg, int(state["frames"]), path)


def _run_dir(who: str, run_dir) -> Path:
    from ppo_torchrl.overrides import check_path

    check_path("run", run_dir, f"{who}(): run_dir={str(run_dir)!r}", "give the run dir (one with checkpoints/)")
    return Path(run_dir)


def _checkpoint(who: str, checkpoint) -> str:
    from ppo_torchrl.errors import ConfigError

    if not isinstance(checkpoint, (str, Path)) or not str(checkpoint).strip():
        raise ConfigError(f"{who}(): checkpoint={checkpoint!r}: give best, last or a checkpoint file")
    return str(checkpoint)


def evaluate_run(run_dir: PathLike, episodes: int = 10, seed: int = 0, checkpoint: str = "best",
                 deterministic: bool = True) -> dict:
    """The eval's figures (return_mean, return_std, per-episode returns and lengths, ...) over `episodes`
    episodes from episode seeds seed * 1000 + i, as `python -m ppo_torchrl.evaluate` computes them; writes nothing.
    episodes and seed are checked as the CLI checks them (whole numbers, at most 10^6 episodes, 32-bit seeds)."""
    from ppo_torchrl.run.checkpoint import load_policy, resolve_checkpoint
    from ppo_torchrl.cli import check_episodes
    from ppo_torchrl.evaluate import evaluate_policy

    episodes, seed = check_episodes(episodes, seed, "evaluate_run(): ")
    deterministic = _flag("evaluate_run(): deterministic", deterministic)
    run_dir = _run_dir("evaluate_run", run_dir)
    cfg, ac, state = load_policy(run_dir, str(resolve_checkpoint(run_dir, _checkpoint("evaluate_run", checkpoint))))
    return evaluate_policy(cfg, ac, state["normalization"]["obs"], episodes, seed, deterministic, progress=False)
