"""The peer row of issue 75 item 3: Stable-Baselines3's PPO on one env at the app's settings for it, one seed.

    python benchmarks/sb3_peer.py --out <dir> env=Hopper-v4 seed=26 [<app override> ...]

The app's config is composed as the training command composes it (the env file's values, then the overrides), and
every value SB3's PPO has a knob for is given to it: batch (n_envs x n_steps), minibatch, epochs, learning rate and
its linear annealing, gamma, lambda, clip range, entropy and value coefficients, gradient clip, target KL, value
clipping, advantage normalization, the layer sizes, activation, orthogonal init and initial log-std, and the
normalization (VecNormalize: running observation statistics, returns scaled by their running std, both clips). What
SB3 has no knob for, where the composed config differs from what SB3 does, is listed in `summary.json` ("lacks") and
on stderr; nothing of it is emulated. Known differences of the same knobs: SB3 anneals the learning rate by the
progress at each update (the app by the update's index), and its target KL stops an epoch's minibatches at 1.5x the
target (the app's `loss.stop_kl` stops the remaining epochs after an epoch's mean passes it).

Figures, as the app's rows report them: the mean raw return of the last 100 training episodes (SB3's own
`ep_info_buffer`, from its Monitor, before any normalization) and a final deterministic eval of 10 episodes on a
fresh env with the statistics frozen (episode seeds seed * 1000 + i). Written: `<out>/summary.json` (refused if it is
there already; nothing else is written until the run ends).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from cli_args import ConfigError, Parser, out_dir
from cli_args import run as run_main

SB3_DEFAULT_HEAD_GAINS = (0.01, 1.0)  # SB3's ortho_init gains of the action and value heads


def sb3_settings(cfg) -> tuple:
    """(PPO kwargs, VecNormalize kwargs, what SB3 lacks) for the composed app config `cfg`."""
    import torch

    lacks = []
    p, loss, adv, opt, col, t = cfg.policy, cfg.loss, cfg.advantage, cfg.optim, cfg.collector, cfg.env.transforms
    if loss.name != "clip_ppo":
        raise ConfigError(f"loss={loss.name}: SB3's PPO is the clipped objective only (loss=clip_ppo)")
    if adv.name != "gae":
        raise ConfigError(f"advantage={adv.name}: SB3's PPO computes GAE only")
    if col.frames_per_batch % col.num_envs:
        raise ConfigError(f"collector.frames_per_batch={col.frames_per_batch} is not a multiple of collector.num_envs")
    width = [p.width] * len(p.hidden_sizes) if p.width else list(p.hidden_sizes)
    critic = [p.width] * len(p.critic_hidden_sizes) if p.width else list(p.critic_hidden_sizes)
    activations = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU, "elu": torch.nn.ELU}
    if p.activation not in activations:
        raise ConfigError(f"policy.activation={p.activation}: not mapped to SB3 (tanh, relu, elu)")
    lr = float(opt.lr)
    ppo = dict(n_steps=col.frames_per_batch // col.num_envs, batch_size=loss.minibatch_size or col.frames_per_batch,
               n_epochs=loss.epochs, learning_rate=(lambda progress: lr * progress) if opt.anneal_lr else lr,
               gamma=adv.gamma, gae_lambda=adv.lmbda, clip_range=loss.clip_epsilon, ent_coef=loss.entropy_coef,
               vf_coef=loss.critic_coef, max_grad_norm=opt.max_grad_norm if opt.max_grad_norm else math.inf,
               target_kl=loss.stop_kl, clip_range_vf=loss.clip_value, normalize_advantage=loss.normalize_advantage,
               policy_kwargs=dict(net_arch=dict(pi=width, vf=critic), activation_fn=activations[p.activation],
                                  ortho_init=p.ortho_init, log_std_init=p.log_std_init))
    if opt.name != "adam" or opt.eps != 1e-5 or opt.weight_decay:
        lacks.append(f"optim={opt.name} eps={opt.eps} weight_decay={opt.weight_decay} (SB3: Adam, eps 1e-5, no decay)")
    if p.head != "normal":
        lacks.append(f"policy.head={p.head} (SB3: a Normal, actions clipped to the bounds)")
    if p.std != "state_independent":
        lacks.append(f"policy.std={p.std} (SB3: a state-independent log-std)")
    if p.std_min or p.std_max is not None:
        lacks.append(f"policy.std_min={p.std_min} std_max={p.std_max} (SB3: no bounds on the std)")
    if p.shared_trunk:
        lacks.append("policy.shared_trunk=true (SB3's MlpPolicy: separate networks here)")
    if p.ortho_init and (p.policy_head_gain, p.value_head_gain) != SB3_DEFAULT_HEAD_GAINS:
        lacks.append(f"policy.policy_head_gain={p.policy_head_gain} value_head_gain={p.value_head_gain} (SB3: 0.01, 1)")
    if loss.critic_loss != "l2":
        lacks.append(f"loss.critic_loss={loss.critic_loss} (SB3: l2)")
    if adv.recompute:
        lacks.append("advantage.recompute=true (SB3: GAE once per batch)")
    if loss.entropy_samples != 1:
        lacks.append(f"loss.entropy_samples={loss.entropy_samples} (SB3: the Normal's exact entropy)")
    if t.obs_norm not in ("running", "none"):
        lacks.append(f"env.transforms.obs_norm={t.obs_norm} (SB3's VecNormalize: running statistics)")
    if t.reward_norm not in ("return", "none"):
        lacks.append(f"env.transforms.reward_norm={t.reward_norm} (SB3's VecNormalize: returns' running std)")
    if t.reward_scale != 1.0:
        lacks.append(f"env.transforms.reward_scale={t.reward_scale} (SB3: none)")
    if list(t.extra):
        lacks.append("env.transforms.extra (TorchRL transforms; SB3: none)")
    norm = dict(norm_obs=t.obs_norm == "running", norm_reward=t.reward_norm == "return", clip_obs=t.obs_clip,
                clip_reward=t.reward_clip, gamma=adv.gamma, epsilon=t.norm_epsilon)
    return ppo, norm, lacks


def printable(settings: dict) -> dict:
    out = {}
    for key, value in settings.items():
        if key == "learning_rate" and callable(value):
            value = "linear from the config's lr to 0"
        elif key == "policy_kwargs":
            value = {k: (v.__name__ if isinstance(v, type) else v) for k, v in value.items()}
        elif isinstance(value, float) and math.isinf(value):
            value = None
        out[key] = value
    return out


def main(argv: list) -> None:
    parser = Parser(description=__doc__.split("\n\n")[0], usage="sb3_peer.py --out DIR env=<env> seed=<s> [override ...]")
    parser.add_argument("--out", type=out_dir, required=True, help="the row's folder (summary.json)")
    parser.add_argument("--episodes", type=int, default=10, help="final deterministic eval episodes (10)")
    args, overrides = parser.parse_known_args(argv)
    if any(o.startswith("-") for o in overrides):
        raise ConfigError(f"unknown option {next(o for o in overrides if o.startswith('-'))}; app overrides are key=value")
    from ppo_torchrl.compose import compose

    cfg = compose(overrides)
    if cfg.env.get("legged") is not None or cfg.env.get("playground") is not None or cfg.env.xml_file:
        raise ConfigError("the peer row runs Gymnasium's registered ids (env=<Hopper-v4 ...> or env=gym env.id=...)")
    ppo, norm, lacks = sb3_settings(cfg)
    summary_path = args.out / "summary.json"
    if summary_path.exists():
        raise ConfigError(f"{summary_path} is there already; give another --out")

    import gymnasium as gym
    import numpy as np
    import stable_baselines3
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(int(cfg.torch_threads))
    env_id, seed = cfg.env.id, int(cfg.seed)
    make_kwargs = dict(cfg.env.make_kwargs or {})
    if cfg.env.max_episode_steps:
        make_kwargs["max_episode_steps"] = int(cfg.env.max_episode_steps)
    frames = math.ceil(cfg.collector.total_frames / cfg.collector.frames_per_batch) * cfg.collector.frames_per_batch
    for line in lacks:
        print(f"sb3_peer: SB3 has no knob for {line}", file=sys.stderr)
    env = VecNormalize(make_vec_env(env_id, n_envs=int(cfg.collector.num_envs), seed=seed, env_kwargs=make_kwargs),
                       **norm)
    model = PPO("MlpPolicy", env, seed=seed, device="cpu", verbose=0, **ppo)
    tick = time.perf_counter()
    model.learn(frames)
    wall = time.perf_counter() - tick
    train_returns = [float(info["r"]) for info in model.ep_info_buffer]

    env.training, env.norm_reward = False, False
    returns = []
    for i in range(args.episodes):
        one = gym.make(env_id, **make_kwargs)
        obs, _ = one.reset(seed=seed * 1000 + i)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(env.normalize_obs(obs[None]), deterministic=True)
            obs, reward, terminated, truncated, _ = one.step(action[0])
            total += float(reward)
            done = terminated or truncated
        returns.append(total)
        one.close()
    args.out.mkdir(parents=True, exist_ok=True)
    summary = {"peer": f"stable-baselines3 {stable_baselines3.__version__} PPO", "env": env_id, "seed": seed,
               "frames": frames, "status": "finished",
               "train_return_last100": float(np.mean(train_returns)) if train_returns else None,
               "train_episodes_in_last100": len(train_returns),
               "eval_return_mean": float(np.mean(returns)), "eval_return_std": float(np.std(returns, ddof=1))
               if len(returns) > 1 else 0.0, "eval_returns": returns, "eval_seeds": f"{seed} * 1000 + 0..{args.episodes - 1}",
               "wall_s": round(wall, 1), "sps": round(frames / wall, 1), "overrides": overrides,
               "settings": printable(ppo), "normalize": norm, "lacks": lacks}
    tmp = summary_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(summary, indent=2) + "\n")
    tmp.replace(summary_path)
    print(f"{env_id} seed {seed}: last-100 train return {summary['train_return_last100']:.1f}, deterministic eval "
          f"{summary['eval_return_mean']:.1f} +- {summary['eval_return_std']:.1f} ({wall:.0f} s): {summary_path}")


if __name__ == "__main__":
    sys.exit(run_main(main))
