"""Export a trained policy as TorchScript: raw observation in, deterministic action out.

    python -m ppo_torchrl.export run=<run dir> [checkpoint=best|last|<file>] [out=<dir>|<file>.pt]

writes <run dir>/policy.pt (out=: that dir's policy.pt, or that .pt file; a shipped run under zoo/ or results/:
outputs/<its path>/policy.pt). The module bakes in the frozen observation normalization and clipping
and the squashing (TanhNormal) or clipping (Normal) to the action bounds, so it runs anywhere
torch runs: `torch.jit.load("policy.pt")(torch.as_tensor(obs, dtype=torch.float32))`, with any
batch shape, no torchrl or ppo_torchrl needed.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Optional

import torch
from torch import nn

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.locks import read, releasing
from ppo_torchrl.rl.models import ActorCritic, to_bounds
from ppo_torchrl.envs.normalization import make_observation_normalizer
from ppo_torchrl.run.rundir import atomic_write_bytes


class DeployedPolicy(nn.Module):
    """obs -> normalize -> clip -> policy net mean -> squash/clip into the action bounds."""

    def __init__(self, ac: ActorCritic, normalizer: nn.Module):
        super().__init__()
        # a frozen copy: the deployed module needs no torch.no_grad() and leaves training weights alone
        self.policy_net = copy.deepcopy(ac.policy_net).cpu().requires_grad_(False)
        # the eval env's normalization, frozen (normalization.FrozenNormalization: float64, as the eval env
        # normalizes the float64 observation before casting to float32): `evaluate` and this module feed the
        # network the same float32 values and act alike, bit for bit
        self.normalize = normalizer
        self.register_buffer("low", ac.action_low.float().cpu())
        self.register_buffer("high", ac.action_high.float().cpu())
        self.squash = ac.head == "tanh_normal"

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return to_bounds(self.policy_net(self.normalize(obs).float())[0], self.low, self.high, self.squash)


def deployed_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict]) -> DeployedPolicy:
    """The run's policy as one module: a raw observation in, the deterministic action out (what policy.pt holds,
    and what the Python API's `load(...).predict` runs)."""
    t = cfg.env.transforms
    if t.extra:  # a user's TorchRL transform (CatFrames keeps a frame buffer) cannot be baked in here
        target = t.extra[0].get("_target_", "?")
        raise ConfigError(f"export: env.transforms.extra[0] ({target}) cannot be baked into policy.pt; "
                          "export supports the built-in normalization and clipping only")
    obs_dim = ac.obs_dim
    normalizer = make_observation_normalizer(t, obs_dim, obs_stats, frozen=True)
    if obs_stats is None:
        normalizer.enabled = False
    return DeployedPolicy(ac, normalizer.module()).eval()


def export_policy(cfg, ac: ActorCritic, obs_stats: Optional[dict], path: Path, owner: Optional[Path] = None) -> Path:
    module = deployed_policy(cfg, ac, obs_stats)
    obs_dim = ac.obs_dim
    example = torch.zeros(2, obs_dim)
    with torch.no_grad():
        scripted = torch.jit.trace(module, example)
    atomic_write_bytes(path, lambda f: torch.jit.save(scripted, f), owner)  # a kill: the old file or the new one
    return path


@releasing  # the shared lock it takes (locks.read) goes when it ends
def main(argv: list[str]) -> Path:
    from ppo_torchrl.run.checkpoint import label, load_policy, resolve_checkpoint
    from ppo_torchrl.cli import parse_args, resolve_run
    from ppo_torchrl.run.ownership import holder
    from ppo_torchrl.run.rundir import check_replaceable, is_run, output_dir_for, record, unwritable
    from ppo_torchrl.usage import EXPORT

    usage, spec, help, about = EXPORT  # usage.py: --help answers before torch is imported
    args = parse_args(argv, spec, usage, help, about)
    run_dir = resolve_run(args["run"])  # run=latest[/<env>]: the newest run dir under outputs/
    read(run_dir)  # a shared lock: no overwrite or run starts there while this reads it (locks.py)
    checkpoint = resolve_checkpoint(run_dir, args["checkpoint"])  # best without a best.pt: last.pt, said so
    out = Path(args["out"]) if args["out"] else None  # out=<dir> (policy.pt in it) or out=<file>.pt
    target = (out if out.suffix == ".pt" else out / "policy.pt") if out is not None else \
        output_dir_for(run_dir, run_dir) / "policy.pt"  # a shipped run (zoo/, results/): under outputs/, its path
    read(holder(target))  # out= in another run dir: that one is read (and written) too
    cfg, ac, state = load_policy(run_dir, str(checkpoint))
    deploy = deploy_paths(target) if cfg.env.get("legged") is not None else []
    check_replaceable(run_dir, [target, *deploy])  # a policy.pt (or policy.json ...) the app did not write: left alone
    why = unwritable(target.parent)
    if why:
        raise ConfigError(f"cannot write {target}: {why}; copy the run dir somewhere writable")
    # a robot: ONNX beside it, the layout it takes, the deploy check; made and checked before anything is written
    files = deploy_files(cfg, ac, state["normalization"]["obs"], target) if cfg.env.get("legged") is not None else []
    path = export_policy(cfg, ac, state["normalization"]["obs"], target, owner=run_dir)
    written = [path, *write_deploy(files, run_dir)]
    if is_run(run_dir):
        record(run_dir, written)
    print(f"exported {cfg.env.id} policy ({label(checkpoint)}, {state['frames']} frames) to {path}"
          + (f"; beside it {', '.join(p.name for p in written[1:])} (python {written[-1].name} policy.json: the "
             "policy in plain MuJoCo)" if len(written) > 1 else ""))
    return path


def deploy_paths(target: Path) -> list:
    """A legged policy's deploy files beside its `<name>.pt`: `<name>.onnx`, `<name>.json`, deploy_mujoco.py."""
    return [target.with_suffix(".onnx"), target.with_suffix(".json"), target.with_name("deploy_mujoco.py")]


def _not_ours_outside_a_run(path: Path, new: bytes) -> Optional[str]:
    """Outside any run dir no manifest says what the app wrote: a file already at `path` with other bytes than
    `new` is a user's (or an older export's) and is left alone; one line says so."""
    from ppo_torchrl.run.ownership import holder

    if holder(path) is not None or not (path.exists() or path.is_symlink()):
        return None
    try:
        if path.is_file() and not path.is_symlink() and path.read_bytes() == new:
            return None
    except OSError:
        pass
    return (f"{path} exists and is not this app's to replace (no run dir holds it); export writes "
            f"{', '.join(p.name for p in deploy_paths(path.with_suffix('.pt'))[:2])} and deploy_mujoco.py beside "
            "the policy: move it away, or give out= a new dir")


def export_deploy(cfg, ac: ActorCritic, obs_stats: Optional[dict], target: Path, owner: Optional[Path]) -> list:
    """Write a legged policy's deploy files beside `target` (its `<name>.pt`): deploy_files, then write_deploy."""
    return write_deploy(deploy_files(cfg, ac, obs_stats, target), owner)


def write_deploy(files: list, owner: Optional[Path]) -> list:
    for path, data in files:
        atomic_write_bytes(path, lambda f, data=data: f.write(data), owner)  # a kill: the old file or the new one
    return [path for path, _ in files]


def deploy_files(cfg, ac: ActorCritic, obs_stats: Optional[dict], target: Path) -> list:
    """[(path, bytes)] of a legged run's deploy files beside its policy `<name>.pt`: `<name>.onnx` (the same module),
    `<name>.json` (the observation layout and action mapping a robot feeds it, and the policy's file name:
    tasks/locomotion/deploy.py) and deploy_mujoco.py (drives it in plain MuJoCo from those alone). Outside a run dir,
    a file already there with other bytes: one ConfigError line, before anything is written."""
    import io
    import json

    from ppo_torchrl.tasks.locomotion import deploy, deploy_mujoco

    module = deployed_policy(cfg, ac, obs_stats)
    obs_dim = ac.obs_dim
    import warnings

    buffer = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # torch.onnx's notes on its TorchScript exporter: nothing a user can act on
        torch.onnx.export(module, (torch.zeros(1, obs_dim, dtype=torch.float64),), buffer, dynamo=False,
                          input_names=["observation"], output_names=["action"],
                          dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}})
    files = list(zip(deploy_paths(target), [
        buffer.getvalue(), json.dumps({**deploy.manifest(cfg), "policy": target.name}, indent=1).encode(),
        Path(deploy_mujoco.__file__).read_bytes()]))
    for path, data in files:
        why = _not_ours_outside_a_run(path, data)
        if why:
            raise ConfigError(why)
    return files


if __name__ == "__main__":
    from ppo_torchrl.cli import run

    run(main)
