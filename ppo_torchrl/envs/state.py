"""The one owner of env-side state: `EnvState`, the first transform of every training env's chain.

An env of `envs.make_torchrl_env` is `TransformedEnv(GymWrapper(...))`; `EnvState` holds, for the envs under
it (in env order):
- the env's rows themselves (env_rows.py: one Gymnasium env per row, or one batched env of N rows; the fast
  collector steps them, evaluate films the first);
- both normalizers (normalization.py): the observation statistics and the return statistics with each env's
  discounted return so far. The `ObservationNormalization` / `RewardNormalization` transforms later in the
  chain apply them to TorchRL's data; they hold no state of their own;
- each env's episode so far (Gymnasium's `RecordEpisodeStatistics`), written to every step and reset as
  TorchRL's `episode_reward` / `step_count` (RewardSum's and StepCounter's keys);
- the env metrics (a step env's curriculum level and recent success rate, a task's reward terms' episode sums: the
  rows' `metrics()`): each env's, averaged once, over every env of every worker, where they are logged
  (`mean_metrics`);
- the statistics of the env's privileged observation (`privileged_norm`, policy.critic_obs=privileged: the
  critic's input, layout.PRIVILEGED), beside the observation's, or None;
- each env's position (positions.py: simulator, time limit, RNG, episode so far, last observation) and the
  normalized observation its policy acts on next (`emit`: the fast collector and the `ObservationNormalization`
  transform tell it here), the rows a resumed run's next reset gives back, and the statistics from before a
  reset that no step has followed yet (a second one puts them back: each first observation counted once).
  The normalizers hold statistics only; this is the one writer of the rest.

Its state is one snapshot, `{"obs", "reward", "privileged", "metrics", "positions"}`, with a small API that every collector
and every scale uses:
- `snapshot()` / `restore(snapshot)`: the whole of it, or the parts given (stats without positions: each
  env stays where it is; positions are held until `continue_episodes` puts each env back);
- `merge(base, parts)`: several workers' snapshots as one: exact pooled statistics, every env's metrics;
- `shared(merged)`: what a worker loads back after a merge (its own discounted returns kept).
TorchRL carries the snapshot as this transform's extra state, so any TorchRL collector's `state_dict()`
(one process, `MultiSyncCollector`, `RayCollector`) holds it in one entry, pickled into one `bytes` value:
TorchRL's workers turn state dicts into TensorDicts, where RNG states and Python floats would not survive.
That value is inside checkpoints too, so `unpack` reads it with safe_pickle's restricted unpickler (data only).
"""

from __future__ import annotations

import pickle
from contextlib import contextmanager
from typing import Dict, List, Optional

import numpy as np
import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, Unbounded
from torchrl.envs.transforms import Transform

from ppo_torchrl.envs.normalization import ObservationNormalizer, RewardNormalizer, pooled
from ppo_torchrl.run.safe_pickle import loads as data_loads

EPISODE_KEYS = ("episode_reward", "step_count")
PACKED = "packed"


class EnvState(Transform):
    """The env-side state of the envs under one `TransformedEnv` (module doc); it changes nothing in the data but
    the episode counters it writes."""

    def __init__(self, rows, obs_norm: ObservationNormalizer, reward_norm: Optional[RewardNormalizer] = None,
                 privileged_norm: Optional[ObservationNormalizer] = None):
        super().__init__(in_keys=[], out_keys=list(EPISODE_KEYS))
        self.rows = rows  # env_rows.GymRows or BatchRows (or envs_playground.PlaygroundRows)
        self.obs_norm, self.reward_norm, self.privileged_norm = obs_norm, reward_norm, privileged_norm
        self.held_positions: Optional[dict] = None  # {"envs", "acted_on"} restored, waiting for continue_episodes
        # What each env's policy acts on next, as it saw it: its last normalized observation (a resume gives it back
        # rather than normalizing the raw one again with statistics that have moved since); the rows the next full
        # reset gives back (continue_episodes(now=False)); the statistics before a full reset no step has followed.
        self._emitted: Optional[np.ndarray] = None
        self._emitted_privileged: Optional[np.ndarray] = None
        self._replay: Optional[np.ndarray] = None
        self._before_reset: Optional[dict] = None

    # ------------------------------------------------------------------ what each policy acts on next
    def emit(self, rows: np.ndarray, mask: Optional[np.ndarray] = None, privileged: Optional[np.ndarray] = None) -> None:
        """The normalized observations each env's policy acts on next: all of them, or the rows of `mask` (a
        partial reset of batched envs); privileged: the normalized privileged observations the critic reads with them
        (the fast collector's, all rows), saved beside them for a bit-exact resume."""
        if privileged is not None:
            self._emitted_privileged = np.asarray(privileged).copy()
        rows = np.asarray(rows)
        if mask is None or self._emitted is None or self._emitted.shape != rows.shape:
            self._emitted = rows.copy()
        else:
            self._emitted[mask] = rows[mask]

    def stepped(self) -> None:
        """An env stepped (the policy acted on the last reset's observations): that reset stays counted."""
        self._before_reset = None

    def full_reset(self) -> None:
        """A reset of every env is about to be normalized: if the last one had no step after it, its observations
        were never acted on, so the statistics go back to before it; either way those of now are kept."""
        norm = self.obs_norm
        if self._before_reset is not None and not norm.frozen:
            norm.stats.load_state_dict(self._before_reset)
        self._before_reset = norm.stats.state_dict()

    @contextmanager
    def uncounted(self):
        """Resets inside it (TorchRL's Collector resets its env once when built, which the fast collector's rollout
        does not use) leave the observation statistics as they were: no policy acts on them."""
        before = self.obs_norm.state_dict()
        yield
        self.obs_norm.load_state_dict(before)

    def take_replay(self) -> Optional[np.ndarray]:
        """The rows a full reset gives back once (continue_episodes(now=False)), else None."""
        replay, self._replay = self._replay, None
        if replay is not None:
            self._before_reset = None
        return replay

    # ------------------------------------------------------------------ the episodes, in TorchRL's keys
    def episodes(self) -> tuple:
        """The return and length of each env's episode so far: ([n], [n]) arrays."""
        return self.rows.episodes()

    def _write_episodes(self, data: TensorDictBase) -> TensorDictBase:
        shape = self.parent.batch_size + (1,)
        returns, lengths = self.episodes()
        data.set("episode_reward", torch.from_numpy(returns).reshape(shape))
        data.set("step_count", torch.from_numpy(lengths).reshape(shape))
        return data

    def _call(self, next_tensordict: TensorDictBase) -> TensorDictBase:
        return self._write_episodes(next_tensordict)

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._write_episodes(tensordict_reset)

    def transform_observation_spec(self, observation_spec: Composite) -> Composite:
        shape = self.parent.batch_size + (1,)
        observation_spec["episode_reward"] = Unbounded(shape=shape, dtype=torch.float64)  # as Gymnasium sums it
        observation_spec["step_count"] = Unbounded(shape=shape, dtype=torch.int64)
        return observation_spec

    # ------------------------------------------------------------------ metrics and positions
    def env_metrics(self) -> List[Dict[str, float]]:
        """Scalars each env keeps, logged each iteration: a step env's curriculum level and recent success rate, a
        task's reward terms' episode sums, one dict per row that says something ([] where none does)."""
        return self.rows.metrics()

    @property
    def gym_envs(self) -> list:
        """The Gymnasium envs of one-env-per-row rows (evaluate films the first; EnvPool reads the id)."""
        return self.rows.envs

    def positions(self) -> list:
        return self.rows.positions()

    def continue_episodes(self, now: bool) -> bool:
        """Each env continues the episode of the positions `restore` held: `now` (the fast collector: the
        observation each policy acts on next is `acted_on()`), or at its next reset (TorchRL's Collector
        resets its envs when it starts; that reset gives back the saved normalized observation, uncounted).
        False, changing nothing, when none are held or their count differs."""
        held, self.held_positions = self.held_positions, None
        if held is None or len(held["envs"]) != self.rows.n:
            return False
        if now:
            self.rows.restore(held["envs"])
        else:
            self.rows.hold(held["envs"])
        if now:
            self._emitted = held["acted_on"]
            self._emitted_privileged = held.get("privileged_acted_on")
        else:
            self._replay = held["acted_on"]
        return True

    # ------------------------------------------------------------------ the state: snapshot, restore, merge
    def snapshot(self, positions: bool = True) -> dict:
        return {"obs": self.obs_norm.state_dict(),
                "reward": self.reward_norm.state_dict() if self.reward_norm is not None else None,
                "privileged": self.privileged_norm.state_dict() if self.privileged_norm is not None else None,
                "metrics": self.env_metrics(),
                "positions": {"envs": self.positions(), "acted_on": self.acted_on(),
                              "privileged_acted_on": self.privileged_acted_on()} if positions else None}

    def acted_on(self) -> Optional[np.ndarray]:
        """The normalized observation each env's policy acts on next (None before any): a copy."""
        return None if self._emitted is None else np.asarray(self._emitted).copy()

    def privileged_acted_on(self) -> Optional[np.ndarray]:
        """The normalized privileged observation the critic reads with `acted_on()` (None where none is written)."""
        return None if self._emitted_privileged is None else self._emitted_privileged.copy()

    def restore(self, snapshot: dict, returns: bool = True) -> None:
        """Load the parts of `snapshot` given: the statistics (each env's discounted return too when
        `returns`), and positions, held for `continue_episodes`."""
        if snapshot.get("obs") is not None:
            self.obs_norm.load_state_dict(snapshot["obs"])
        if snapshot.get("reward") is not None and self.reward_norm is not None:
            self.reward_norm.load_state_dict(snapshot["reward"], running=returns)
        if snapshot.get("privileged") is not None and self.privileged_norm is not None:
            self.privileged_norm.load_state_dict(snapshot["privileged"])
        if snapshot.get("positions") is not None:
            self.held_positions = snapshot["positions"]

    @staticmethod
    def merge(base: Optional[dict], parts: List[dict]) -> dict:
        """The workers' snapshots as one: each part is `base` (the stats every worker started the batch from)
        plus what that worker added; the result holds all of it exactly (normalization.pool), and every env's
        metrics. No positions: each env stays."""
        base = base or {}
        reward_parts = [p["reward"] for p in parts if p.get("reward") is not None]
        return {"obs": pooled(base.get("obs"), [p.get("obs") for p in parts]),
                "reward": pooled(base.get("reward"), reward_parts) if reward_parts else None,
                "privileged": pooled(base.get("privileged"), [p.get("privileged") for p in parts]),
                "metrics": [m for p in parts for m in p.get("metrics") or []],
                "positions": None}

    @staticmethod
    def shared(merged: dict, own: dict) -> dict:
        """What a worker whose snapshot is `own` loads after a merge: the merged statistics, its own envs'
        discounted returns, no positions (each env stays where it is)."""
        reward = merged.get("reward")
        if reward is not None and own.get("reward") is not None:
            reward = {**reward, "returns": own["reward"]["returns"]}
        return {"obs": merged.get("obs"), "reward": reward, "privileged": merged.get("privileged"),
                "metrics": merged.get("metrics"), "positions": None}

    # ------------------------------------------------------------------ TorchRL's face of the state
    def get_extra_state(self) -> dict:
        return pack(self.snapshot())

    def set_extra_state(self, state) -> None:
        snapshot = unpack(state)
        if snapshot:
            self.restore(snapshot)


def unpack(state) -> Optional[dict]:
    """What `pack` made, as it comes back from anywhere (a TensorDict from a worker too); None if not packed."""
    if state is None:
        return None
    if hasattr(state, "to_dict"):
        state = state.to_dict()
    packed = dict(state).get(PACKED)
    if packed is None:
        return None
    if isinstance(packed, torch.Tensor):  # bytes that travelled as a uint8 tensor
        packed = packed.numpy().tobytes()
    return data_loads(packed)  # data only: a crafted state is refused (safe_pickle.Refused), never run


def pack(state: dict) -> dict:
    """A state as TorchRL's worker processes pass it best: one pickled `bytes` entry. They turn a state dict
    into a TensorDict and send each tensor through shared memory, ~2 ms apiece and ~20 ms a round trip for a
    dozen (RNG states and Python floats would not survive it); one `bytes` entry stays one plain message."""
    return {PACKED: pickle.dumps(state)}


def check_packed(tree) -> None:
    """Read every packed state in `tree` (a loaded checkpoint), nested ones too, so that a crafted one is refused
    (safe_pickle.Refused) when its file is loaded, not later in a worker."""
    if isinstance(tree, dict):
        packed = tree.get(PACKED)
        if isinstance(packed, (bytes, torch.Tensor)):
            check_packed(unpack(tree))
        for value in tree.values():
            check_packed(value)
    elif isinstance(tree, (list, tuple)):
        for value in tree:
            check_packed(value)


def env_state_of(env) -> EnvState:
    """The EnvState of an env of `envs.make_torchrl_env` (TypeError for any other env)."""
    transforms = list(getattr(env, "transform", None) or [])
    state = next((t for t in transforms if isinstance(t, EnvState)), None)
    if state is None:
        raise TypeError("not an env of envs.make_torchrl_env (no EnvState transform)")
    return state


def mean_metrics(reports: List[Dict[str, float]]) -> Dict[str, float]:
    """The env metrics as logged: each key's mean over every env that reports it ({} for none)."""
    keys = dict.fromkeys(k for r in reports for k in r)
    return {k: float(np.mean([r[k] for r in reports if k in r])) for k in keys}
