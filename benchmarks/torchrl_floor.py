"""How fast TorchRL's stock Collector over a TorchRL env can go here, whatever the transforms: the floor
under the `env.transforms.extra` path (issue 30's goal: 2x that path's 2026-11-25 frames/s).

Times one 2048-frame batch of `torchrl.collectors.Collector` (one Hopper-v4 env, the app's lean sampling
policy), A B A B, for:
  app        the app's TorchRL path with CatFrames(N=2) in env.transforms.extra (what a user runs)
  bare       GymWrapper with DoubleToFloat alone (no statistics, no episode counts, no CatFrames)
  lean       a minimal EnvBase over the same Gymnasium env (its _step builds one float32 TensorDict), no transform
  lean+cat   the minimal EnvBase with CatFrames(N=2) alone
`bare` and `lean` drop what the app needs (normalization, episode counts), so they bound from below what
any set of transforms can cost on this Collector. Prints one JSON line per round.

    .venv/bin/python benchmarks/torchrl_floor.py [--rounds 3]
"""

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

warnings.filterwarnings("ignore")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

import numpy as np  # noqa: E402
import torch  # noqa: E402
from tensordict import TensorDict  # noqa: E402
from torchrl.collectors import Collector  # noqa: E402
from torchrl.data import Bounded, Categorical, Composite, Unbounded  # noqa: E402
from torchrl.envs import CatFrames, DoubleToFloat, EnvBase, GymWrapper, TransformedEnv  # noqa: E402

from conftest import compose_config  # noqa: E402
from ppo_torchrl.envs.make import env_spec, make_gym_env, make_torchrl_env  # noqa: E402
from ppo_torchrl.rl.models import make_actor_critic, sampling_policy  # noqa: E402

CAT = "+env.transforms.extra=[{_target_: torchrl.envs.CatFrames, N: 2, dim: -1, in_keys: [observation]}]"


class MinimalEnv(EnvBase):
    """One Gymnasium env as a TorchRL env with nothing but the step: the least a TorchRL env can do."""

    def __init__(self, gym_env):
        super().__init__(batch_size=torch.Size([]))
        self.gym_env, self.last_obs = gym_env, None
        space = gym_env.action_space
        self.observation_spec = Composite(observation=Unbounded(gym_env.observation_space.shape))
        self.action_spec = Bounded(torch.as_tensor(space.low), torch.as_tensor(space.high), space.shape)
        self.reward_spec = Unbounded((1,))
        self.done_spec = Composite(done=Categorical(2, (1,), dtype=torch.bool),
                                   terminated=Categorical(2, (1,), dtype=torch.bool),
                                   truncated=Categorical(2, (1,), dtype=torch.bool))

    def _step(self, td):
        obs, reward, terminated, truncated, _ = self.gym_env.step(td.get("action").numpy())
        end = torch.tensor([terminated, truncated])
        return TensorDict({"observation": torch.from_numpy(obs).float(), "reward": torch.tensor([reward], dtype=torch.float32),
                           "done": end.any().reshape(1), "terminated": end[:1], "truncated": end[1:]})

    def _reset(self, td=None, **kwargs):
        obs, _ = self.gym_env.reset()
        no = torch.zeros(1, dtype=torch.bool)
        return TensorDict({"observation": torch.from_numpy(obs).float(), "done": no, "terminated": no.clone(),
                           "truncated": no.clone()})

    def _set_seed(self, seed):
        self.gym_env.reset(seed=seed)


def build(kind: str, cfg):
    if kind == "app":
        return make_torchrl_env(cfg.env, clip_actions=False, gamma=0.99, seed=1)
    gym_env = make_gym_env(cfg.env)
    gym_env.reset(seed=1)
    if kind == "bare":
        return TransformedEnv(GymWrapper(gym_env), DoubleToFloat())
    env = MinimalEnv(gym_env)
    return TransformedEnv(env, CatFrames(N=2, dim=-1, in_keys=["observation"])) if kind == "lean+cat" else env


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    kinds = ("app", "bare", "lean", "lean+cat")
    cfgs = {k: compose_config(["env=Hopper-v4", *([CAT] if k == "app" else [])]) for k in kinds}
    policies = {k: sampling_policy(make_actor_critic(c.policy, env_spec(c.env))) for k, c in cfgs.items()}
    policies["lean+cat"] = policies["app"]  # 22 inputs: two stacked frames
    collectors = {k: Collector(build(k, cfgs[k]), policies[k], frames_per_batch=2048, total_frames=-1,
                               auto_register_policy_transforms=False) for k in kinds}
    iterators = {k: iter(c) for k, c in collectors.items()}
    for it in iterators.values():
        next(it)  # warm-up
    for r in range(args.rounds):
        row = {"round": r + 1}
        for k in kinds:
            t0 = time.perf_counter()
            next(iterators[k])
            row[k] = round(2048 / (time.perf_counter() - t0))
        print(json.dumps({**row, "unit": "frames/s"}), flush=True)
    for c in collectors.values():
        c.shutdown()


if __name__ == "__main__":
    main()
