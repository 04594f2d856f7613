"""`collector.backend=envpool`: FastCollector's rollout over EnvPool, which steps the Gymnasium MuJoCo tasks in C++.

Why: the env step is most of a run's time; EnvPool (`envpool` 1.2.5, its own MuJoCo 3.6.0) steps the same tasks
as Gymnasium's (tests/test_envpool.py: Hopper and Walker2d agree to ~1e-12 over whole episodes; HalfCheetah to
~1e-9 over 20 steps, then round-off grows; Ant and Humanoid to ~1e-5 a step: their contact solver differs between
the two MuJoCo versions, so their trajectories agree statistically, not per step).

What it is: a `torchrl.collectors.Collector` (a FastCollector subclass: the same batch keys, policy, RNG, state
and weight sync, so `MultiSyncCollector` and `RayCollector` run it in workers), over the same
`TransformedEnv(GymWrapper(...))` as every path, whose `EnvState` keeps the statistics: the observations and
rewards go through `EnvState.obs_norm` / `reward_norm` as on the fast path. Only the envs it steps are
different: one EnvPool of `collector.num_envs` envs made from the Gymnasium env's own id and make kwargs. The
Gymnasium envs stay the carrier TorchRL's Collector resets, and evaluation, video and export run on them.

EnvPool's auto-reset: the step after an episode's end is a reset step whose action is ignored and whose reward
is 0. Here it is taken at once, for the ended envs only (`step(..., env_id=ended)`), as Gymnasium's reset: it
gives the new episode's first observation and never enters a batch.

Resume: EnvPool cannot restore a simulator state. A resumed run keeps the statistics, the RNG and the frame count
(the trainer's); each env starts a new episode (the start line says so).
"""

from __future__ import annotations

import numpy as np
import torch
from tensordict import TensorDict

from ppo_torchrl.collectors.fast import Buffers, FastCollector
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.internals import OWN, worker_parts

INSTALL = 'pip install -e ".[envpool]" (make setup installs it; EnvPool has wheels for Python >= 3.11)'
# The Gymnasium MuJoCo ids EnvPool 1.2.5 steps (envpool.list_all_envs()), v4 and v5
TASKS = ("Ant", "HalfCheetah", "Hopper", "Humanoid", "HumanoidStandup", "InvertedDoublePendulum",
         "InvertedPendulum", "Pusher", "Reacher", "Swimmer", "Walker2d")
ENV_IDS = tuple(f"{task}-v{v}" for task in TASKS for v in (4, 5))
# Gymnasium's (low, high) make kwargs, which EnvPool takes as two values
RANGES = {"healthy_z_range": "healthy_z", "healthy_angle_range": "healthy_angle",
          "healthy_state_range": "healthy_state", "contact_force_range": "contact_force"}
RESUME_LIMIT = ("collector.backend=envpool cannot restore a simulator state: the statistics, RNG and frame count "
                "carry on, each env starts a new episode")


def check_envpool(cfg) -> None:
    """One line unless collector.backend=envpool can run this config: EnvPool installed, an id it has, no model
    file, no per-step TorchRL transforms, make kwargs it takes."""
    env = cfg.env
    if env.id not in ENV_IDS or env.get("xml_file"):
        raise ConfigError(f"collector.backend=envpool steps Gymnasium's MuJoCo ids that EnvPool has "
                          f"({', '.join(t + '-v4/v5' for t in TASKS)}), not env.id={env.id}"
                          + (" with env.xml_file" if env.get("xml_file") else ""))
    if env.transforms.extra:
        raise ConfigError("env.transforms.extra needs collector.backend=torchrl (or auto): the envpool collector "
                          "runs no TorchRL transform per step")
    try:
        import envpool
    except ImportError:
        raise ConfigError(f"collector.backend=envpool needs EnvPool, which is not installed: {INSTALL}") from None
    known = envpool.make_spec(env.id).config._fields
    for key in (env.make_kwargs or {}):
        if RANGES.get(key, key) + ("_min" if key in RANGES else "") not in known:
            raise ConfigError(f"env.make_kwargs.{key} is not a setting EnvPool's {env.id} has; use "
                              "collector.backend=fast for it")


def pool_kwargs(gym_env) -> dict:
    """EnvPool's make kwargs for the Gymnasium env `gym_env` (its registered id, make kwargs and time limit)."""
    spec = gym_env.spec
    kwargs = {}
    for key, value in (spec.kwargs or {}).items():
        if key in RANGES:
            kwargs[f"{RANGES[key]}_min"], kwargs[f"{RANGES[key]}_max"] = (float(v) for v in value)
        elif key not in ("render_mode",):
            kwargs[key] = value
    if spec.max_episode_steps is not None:
        kwargs["max_episode_steps"] = int(spec.max_episode_steps)
    return kwargs


class EnvpoolCollector(FastCollector):
    """FastCollector's rollout with the envs stepped by one EnvPool (module doc)."""

    def __init__(self, create_env_fn, policy=None, **kwargs):
        super().__init__(create_env_fn, policy, **kwargs)
        self.pool = None  # built at the first rollout, seeded from self.rng
        self.env_id = self.env_state.gym_envs[0].spec.id
        self.kwargs = pool_kwargs(self.env_state.gym_envs[0])
        self.returns = np.zeros(self.num_envs)  # each env's episode so far (Gymnasium's counters, kept here)
        self.lengths = np.zeros(self.num_envs, np.int64)

    def set_seed(self, seed: int, static_seed: bool = False) -> int:
        out = super().set_seed(seed, static_seed)
        self._close_pool()  # the next rollout starts new episodes, seeded from the new RNG
        return out

    def _close_pool(self) -> None:
        if self.pool is not None:
            self.pool.close()
        self.pool, self._obs = None, None

    def _ordered(self, result: tuple, rows: np.ndarray) -> tuple:
        """EnvPool's (obs, reward, terminated, truncated, info) in the order of `rows`."""
        obs, reward, term, trunc, info = result
        order = np.argsort(info["env_id"])
        if not np.array_equal(info["env_id"][order], rows):
            raise RuntimeError(f"EnvPool answered envs {info['env_id']} for {rows}")
        return obs[order], reward[order], term[order], trunc[order], info["elapsed_step"][order]

    def _current_obs(self) -> np.ndarray:
        if self.pool is None:
            import envpool

            seed = int(self.rng.integers(2**31 - 1))
            self.pool = envpool.make(self.env_id, env_type="gymnasium", num_envs=self.num_envs, seed=seed,
                                     num_threads=min(self.num_envs, 4), **self.kwargs)
            raw, info = self.pool.reset()
            raw = raw[np.argsort(info["env_id"])]
            self._obs = self.obs_norm(raw, update=True)
            self.returns[:], self.lengths[:] = 0.0, 0
            self.env_state.stepped()
            self.env_state.emit(self._obs)
        return self._obs

    @torch.no_grad()
    def rollout(self) -> TensorDict:
        n, steps = self.num_envs, self.steps
        obs = self._current_obs()
        policy = self.numpy_policy
        policy.sync()
        act_dim = policy.low.shape[0]
        b = Buffers(steps, n, obs.shape[1], act_dim)
        noise = self.rng.standard_normal((steps, n, act_dim), dtype=np.float32)
        every = np.arange(n)
        pool, act, normalize, scale_rewards = self.pool, policy.act, self.obs_norm, self.reward_norm
        for t in range(steps):
            b.obs[t] = obs
            b.traj[t] = self._traj_ids
            b.action[t], to_env = act(obs, noise[t])
            raw, reward, term, trunc, _ = self._ordered(pool.step(to_env.astype(np.float64), every), every)
            reward = reward.astype(np.float64)
            self.returns += reward
            self.lengths += 1
            b.ep_return[t], b.ep_length[t] = self.returns, self.lengths
            b.terminated[t], b.truncated[t] = term, trunc
            done = term | trunc
            next_obs = obs = normalize(raw)
            if done.any():
                ended = np.flatnonzero(done)
                # EnvPool's reset step for the ended envs alone: the new episodes' first observations (module doc)
                first, r0, _, _, elapsed = self._ordered(pool.step(np.zeros((len(ended), act_dim)), ended), ended)
                if elapsed.any() or r0.any():
                    raise RuntimeError("EnvPool's step after an episode's end was not its reset step")
                obs = next_obs.copy()
                obs[ended] = normalize(first)
                self.returns[ended], self.lengths[ended] = 0.0, 0
                for i in ended:
                    self._traj_ids[i] = self._traj_ids.max() + 1
            b.next_obs[t] = next_obs
            b.reward[t] = scale_rewards(reward, done)
        self._obs = obs
        self.env_state.emit(obs)
        return self._fill(b)

    def load_state_dict(self, state_dict, **kwargs) -> None:
        """A saved state: the statistics and the RNG; EnvPool cannot restore a simulator state, so the saved
        positions are dropped and each env starts a new episode (RESUME_LIMIT). The merged statistics between
        batches (no OWN entry): each env goes on where it is."""
        own = worker_parts(state_dict)[0].get(OWN)
        super().load_state_dict(state_dict, **kwargs)
        self.env_state.held_positions = None  # the Gymnasium envs' positions: nothing here steps them
        if own is not None:  # a resume: new episodes, drawn from the restored RNG
            self.rng.bit_generator.state = own["rng"]
            self._close_pool()

    def shutdown(self, *args, **kwargs) -> None:
        self._close_pool()
        super().shutdown(*args, **kwargs)
