"""Export a trained policy as TorchScript: raw observation in, deterministic action out.

    python -m ppo_torchrl.export run=<run dir> [checkpoint=best|last|<file>]

writes <run dir>/policy.pt. The module bakes in the frozen observation normalization and clipping
and the squashing (TanhNormal) or clipping (Normal) to the action bounds, so it runs anywhere
torch runs: `torch.jit.load("policy.pt")(torch.as_tensor(obs, dtype=torch.float32))`, with any
batch shape, no torchrl or ppo_torchrl needed.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Optional

import numpy as np
import torch
from torch import nn

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.models import ActorCritic, to_bounds
from ppo_torchrl.normalization import obs_scale


class DeployedPolicy(nn.Module):
    """obs -> normalize -> clip -> policy net mean -> squash/clip into the action bounds."""

    def __init__(self, ac: ActorCritic, obs_stats: Optional[dict], obs_clip: Optional[float], epsilon: float):
        super().__init__()
        # a frozen copy: the deployed module needs no torch.no_grad() and leaves training weights alone
        self.policy_net = copy.deepcopy(ac.policy_net).cpu().requires_grad_(False)
        obs_dim = ac.policy_net[0][0].in_features
        mean = np.zeros(obs_dim) if obs_stats is None else np.asarray(obs_stats["mean"])
        std = np.ones(obs_dim) if obs_stats is None else obs_scale(obs_stats["var"], epsilon)
        # float64, as the eval env normalizes (ObservationNorm on the float64 observation, then DoubleToFloat):
        # `evaluate` and this module then feed the network the same float32 values and act alike, bit for bit
        self.register_buffer("obs_mean", torch.as_tensor(mean, dtype=torch.float64))
        self.register_buffer("obs_std", torch.as_tensor(std, dtype=torch.float64))
        clip = float(obs_clip) if obs_stats is not None and obs_clip is not None else float("inf")
        self.register_buffer("obs_clip", torch.tensor(clip, dtype=torch.float64))
        self.register_buffer("low", ac.action_low.float().cpu())
        self.register_buffer("high", ac.action_high.float().cpu())
        self.squash = ac.head == "tanh_normal"

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = ((obs.double() - self.obs_mean) / self.obs_std).clamp(-self.obs_clip, self.obs_clip).float()
        return to_bounds(self.policy_net(x)[0], self.low, self.high, self.squash)


def export_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], path: Path) -> Path:
    t = cfg.env.transforms
    if t.extra:  # a user's TorchRL transform (CatFrames keeps a frame buffer) cannot be baked in here
        target = t.extra[0].get("_target_", "?")
        raise ConfigError(f"export: env.transforms.extra[0] ({target}) cannot be baked into policy.pt; "
                          "export supports the built-in normalization and clipping only")
    module = DeployedPolicy(ac, obs_stats, t.obs_clip, t.norm_epsilon).eval()
    example = torch.zeros(2, module.obs_mean.shape[0])
    with torch.no_grad():
        scripted = torch.jit.trace(module, example)
    path.parent.mkdir(parents=True, exist_ok=True)
    scripted.save(str(path))
    return path


def main(argv: list[str]) -> Path:
    from ppo_torchrl.checkpoint import load_policy
    from ppo_torchrl.cli import parse_args, resolve_run
    from ppo_torchrl.rundir import is_run, record, unwritable

    usage = "python -m ppo_torchrl.export run=<run dir> [checkpoint=best|last|<file>]"
    help = {"run": "the run dir whose policy is exported (or latest, latest/<env>); writes <run dir>/policy.pt",
            "checkpoint": "best, last, or a checkpoint file"}
    about = ("Writes the policy as TorchScript: a raw observation in, the deterministic action within the bounds\n"
             "out, normalization baked in; it runs with torch alone: torch.jit.load('policy.pt')(obs).")
    args = parse_args(argv, {"run": None, "checkpoint": "best"}, usage, help, about)
    run_dir = resolve_run(args["run"])  # run=latest[/<env>]: the newest run dir under outputs/
    cfg, ac, state = load_policy(run_dir, args["checkpoint"])
    why = unwritable(run_dir)
    if why:
        raise ConfigError(f"cannot write {run_dir / 'policy.pt'}: {why}; copy the run dir somewhere writable")
    path = export_policy(cfg, ac, state["normalization"]["obs"], run_dir / "policy.pt")
    if is_run(run_dir):
        record(run_dir)
    print(f"exported {cfg.env.id} policy ({args['checkpoint']}, {state['frames']} frames) to {path}")
    return path


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
