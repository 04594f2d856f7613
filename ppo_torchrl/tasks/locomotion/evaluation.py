"""Evaluating a legged task: its episodes run side by side in the rows of one batch (each row takes the next episode
seed when its episode ends), the policy deterministic on frozen statistics, the gait sampled at every physics step
(robots/gait.py's GaitMeter, one per row). The record is evaluate.run_episodes' (evaluate.summarize reads it), so an
episode seeded `s` starts from the state a one-env evaluation of seed `s` starts from. A filmed evaluation runs its
episodes one at a time in one row (the video follows row 0).
"""

from __future__ import annotations

from typing import Optional, Sequence

import numpy as np
import torch

from ppo_torchrl.robots.gait import GaitMeter
from ppo_torchrl.tasks.locomotion.sensors import Contacts
from ppo_torchrl.tasks.locomotion.world import FOOT, NON_FOOT

MAX_ROWS = 32  # episodes in flight at once (an evaluation of fewer runs that many)


class GaitBatch:
    """A GaitMeter per row, fed at every physics step by the batch (batch.py `_substep_rows`)."""

    def __init__(self, n: int, world, speed_limit: Optional[float]):
        self.world = world
        self.meters = [GaitMeter(len(world.feet), speed_limit, list(world.corners) if world.corners else None)
                       for _ in range(n)]
        self.contacts = Contacts(1, world)

    def reset(self, i: int) -> None:
        self.meters[i].reset()

    def sample(self, i: int, data, joint_speed: float, dt: float, moving: bool) -> None:
        w = self.world
        partners, _ = self.contacts.partners(data)
        kinds = w.kind[partners]
        feet = np.zeros(len(w.feet), bool)
        feet[w.foot_index[partners[kinds == FOOT]]] = True
        body = bool((kinds == NON_FOOT).any())
        torque = None if w.torque_limit is None else \
            float((np.abs(data.qfrc_actuator[w.act_dofs]) / w.torque_limit).max())
        self.meters[i].add(feet, joint_speed, body, dt, moving, torque)


@torch.no_grad()
def task_episodes(make_batch, cfg, ac, obs_stats: Optional[dict], seeds: Sequence[int], deterministic: bool = True,
                  video_path=None, progress: Optional[bool] = None, video_episodes: Sequence[int] = (0,),
                  video_length: Optional[float] = None, elsewhere: int = 0) -> dict:
    """evaluate.run_episodes for a legged task (module doc): one episode per seed, the same record. make_batch:
    envs.make_batch (the batch of the task's config)."""
    from ppo_torchrl.envs.filming import VIDEO_SIZE, EpisodeProgress, Filming
    episodes = len(seeds)
    rows = 1 if video_path is not None else max(1, min(episodes, MAX_ROWS))
    render = {"render_mode": "rgb_array", "width": VIDEO_SIZE[0], "height": VIDEO_SIZE[1]} if video_path else {}
    batch = make_batch(cfg.env, rows, evaluation=True, **render)
    world, task = batch.world, batch.task
    batch.spec = _Spec(batch.max_steps)
    batch.gait = GaitBatch(rows, world, cfg.env.locomotion.get("joint_speed_limit"))
    act = eval_policy(cfg, ac, obs_stats, batch, rows, deterministic, int(seeds[0]) if len(seeds) else 0)
    film = (Filming(video_path, batch, [e for e in video_episodes if 0 <= e < episodes], video_length)
            if video_path is not None else None)
    record = {k: [None] * episodes for k in ("returns", "lengths", "distances", "gaits", "crossed", "heights",
                                             "terminated", "ends")}
    shown = EpisodeProgress(episodes, progress, elsewhere=elsewhere)
    episode_of = np.full(rows, -1)
    start_xy = np.zeros((rows, 2))
    callbacks = [None] * rows
    following, done_count = 0, 0

    rewards = [[] for _ in range(rows)]

    def begin(i: int) -> None:
        nonlocal following
        episode_of[i] = following
        rewards[i] = []
        if following < episodes:
            # as a one-env evaluation starts an episode: TorchRL's set_seed resets the env with the seed, then the
            # rollout's reset draws the episode (so the episode seeded s is that env's second draw)
            batch.reset_row(i, int(seeds[following]))
            batch.reset_row(i)
            start_xy[i] = batch.datas[i].qpos[:2]
            callbacks[i] = film.start(following) if film is not None else None
            if callbacks[i] is not None:
                import functools

                film.on_frame = functools.partial(shown.filming, following, film, [n for n in record["lengths"]
                                                                                   if n is not None])
            following += 1

    for i in range(rows):
        begin(i)
    try:
        while done_count < episodes:
            obs, reward, terminated, truncated, _ = batch.step(act(batch.last_obs))
            done = terminated | truncated
            for i in range(rows):
                e = episode_of[i]
                if e < 0 or e >= episodes:
                    continue
                rewards[i].append(reward[i])
                if not done[i]:
                    if callbacks[i] is not None:
                        callbacks[i]()
                    continue
                _record(record, e, batch, i, start_xy[i], bool(terminated[i]))
                # the return as TorchRL's rollout sums it (float32 rewards), so a one-env evaluation's figure to the bit
                record["returns"][e] = float(torch.tensor(rewards[i], dtype=torch.float32).sum())
                done_count += 1
                if film is not None:
                    shown.update(done_count, film.spent_s, film.left_s(done_count, [n for n in record["lengths"]
                                                                                    if n is not None]))
                else:
                    shown.update(done_count)
                begin(i)
    finally:
        video = film.close() if film is not None else None
        batch.close()
    has_step = task.terrain.has_step
    return {"returns": record["returns"], "lengths": record["lengths"], "distances": record["distances"],
            "gaits": record["gaits"], "crossed": record["crossed"] if has_step else [],
            "heights": record["heights"] if has_step else [], "dt": world.dt,
            "success_margin": task.terrain.success_margin if has_step and episodes else None, "video": video,
            "terminated": record["terminated"], "ends": record["ends"], "seeds": list(seeds),
            "feet": tuple(world.foot_names), "figures": "locomotion"}


def eval_policy(cfg, ac, obs_stats: Optional[dict], batch, rows: int, deterministic: bool, seed: int = 0):
    """The evaluation's policy for `rows` rows of `batch`: raw observations in, actions out, on frozen statistics;
    deterministic: as a one-env evaluation's TorchRL env and actor compute it (row by row)."""
    from ppo_torchrl.rl.array_policy import policy_of

    return policy_of(cfg, ac, obs_stats, batch.task.obs_dim, batch.observation_layout(), batch.world.model.nu, rows,
                     deterministic, seed)


def _record(record: dict, e: int, batch, i: int, start_xy, terminated: bool) -> None:
    """Episode e, which row i just ended: its figures in the record."""
    task, world, m = batch.task, batch.world, batch.task.memory
    qpos = batch.datas[i].qpos
    record["returns"][e], record["lengths"][e] = float(m.returns[i]), int(m.lengths[i])
    record["terminated"][e], record["ends"][e] = terminated, task.termination(i)
    moved = qpos[:2] - start_xy
    record["distances"][e] = (float(moved @ world.heading), float(qpos[0]))
    record["gaits"][e] = batch.gait.meters[i].summary()
    if task.terrain.has_step:
        record["crossed"][e] = task.terrain.crossed(i, batch.datas[i].xpos[world.trunk, :2])
        record["heights"][e] = float(task.terrain.height[i])


class _Spec:
    """What Filming reads of a Gymnasium env's spec: its time limit."""

    def __init__(self, max_episode_steps: int):
        self.max_episode_steps = max_episode_steps
