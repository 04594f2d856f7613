"""The batched legged env: N robots of one model as one Gymnasium vector env (TorchRL's GymWrapper takes it as an
env of batch size N; the fast collector steps it in one call), each row reset on its own.

Physics: each row has its own MjModel copy (its step, its world) and MjData; a control step sets every row's
control and calls `mj_step(nstep=frame_skip)` and `mj_rnePostConstraint` (what Gymnasium's MuJoCo envs call), rows
split over a thread pool: MuJoCo's bindings release the GIL inside each call, so the rows step in parallel in C
(measured against `mujoco.rollout`'s pool, docs/speed.md: as fast, and the rows' MjData stay readable). Where the
task needs each physics step (the joint-speed-limit cost, evaluate's gait figures) the rows are stepped one physics
step at a time. What the task reads is then gathered into arrays over the rows (task.Reading), and the task
(task.py) computes observations, rewards and endings as arrays.

A row is what one env of the locomotion env before the rebuild was (robots/env.py, gone; tests/legged_reference.py):
seeded as Gymnasium seeds an env (`seed + i`), it draws its step and its reset noise from its own RNG in the same
order, so the same actions from the same state give the same physics states, and its position (`row_position`: the
simulator's integration state, the time limit's counter, the RNG, the episode memory, the terrain's row) restores it
bit for bit (a resumed run continues as the uninterrupted one)."""

from __future__ import annotations

import os
import time
from concurrent.futures import ThreadPoolExecutor
from typing import List, Optional, Sequence

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.utils import seeding

from ppo_torchrl.tasks.locomotion.task import LeggedTask, Reading
from ppo_torchrl.tasks.locomotion.world import build_world

DEFAULT_MAX_STEPS = 1000  # Gymnasium's Ant-v5 (the locomotion env's registered limit)
STATE = mujoco.mjtState.mjSTATE_INTEGRATION


def physics_threads(asked: Optional[int], n: int) -> int:
    """Threads stepping the rows: asked (> 0), else one per core, at most one per row."""
    return max(1, min(int(asked) if asked else (os.cpu_count() or 1), n))


class LeggedBatchEnv(gym.vector.VectorEnv):
    """N rows of one legged task (module doc). kwargs: envs.gym_make_kwargs of env=legged."""

    metadata = {"autoreset_mode": gym.vector.AutoresetMode.DISABLED, "render_modes": ["rgb_array"]}

    def __init__(self, kwargs: dict, num_envs: int = 1, evaluation: bool = False, threads: Optional[int] = None,
                 render_mode: Optional[str] = None, width: int = 640, height: int = 480, privileged: bool = False, **_):
        kwargs = dict(kwargs)
        self.max_steps = int(kwargs.pop("max_episode_steps", None) or DEFAULT_MAX_STEPS)
        self.world = world = build_world(kwargs, render=render_mode is not None)
        self.num_envs = n = int(num_envs)
        self.models = [world.row_model() for _ in range(n)]
        self.datas = [mujoco.MjData(m) for m in self.models]
        for d in self.datas:
            d.qpos[:] = world.init_qpos
            mujoco.mj_kinematics(world.model, d)
        self.rngs = [seeding.np_random()[0] for _ in range(n)]
        # privileged: the critic's observation is asked for (policy.critic_obs=privileged): the feet's contacts are kept
        self.task = task = LeggedTask(n, world, kwargs, evaluation, privileged)
        self.noise = task.noise
        model = world.model
        self.reading = Reading(qpos=np.zeros((n, model.nq)), qvel=np.zeros((n, model.nv)),
                               xpos=np.zeros((n, model.nbody, 3)), trunk_xmat=np.zeros((n, 9)),
                               feet_xy=np.zeros((n, len(world.feet), 2)), actuator_force=np.zeros((n, model.nu)),
                               cfrc_ext=np.zeros((n, model.nbody, 6)) if task.needs_cfrc else None,
                               step_peak=np.zeros((n, len(world.act_dofs))) if task.needs_peak else None)
        for i in range(n):
            self._gather(i)
        self.last_obs = np.zeros((n, task.obs_dim))
        self.pending: Optional[List[Optional[dict]]] = None  # positions the next reset of each row continues
        self.gait = None  # evaluate sets a GaitMeter batch (gait.py): sampled at every physics step
        self.threads = physics_threads(threads, n)
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self._chunks = [range(k, n, self.threads) for k in range(self.threads)]
        self.render_mode, self.width, self.height = render_mode, int(width), int(height)
        self._renderer = None
        if render_mode is not None:  # row 0 is filmed: its floor drawn to the horizon, its buffer the video's size
            from ppo_torchrl.envs.mjcf import floor_to_the_horizon

            filmed = self.models[0]
            floor_to_the_horizon(filmed)
            filmed.vis.global_.offwidth = max(filmed.vis.global_.offwidth, self.width)
            filmed.vis.global_.offheight = max(filmed.vis.global_.offheight, self.height)
        self.timing: Optional[dict] = None  # {"physics": s, "task": s} accumulated when set (benchmarks/legged_speed.py)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (task.obs_dim,), np.float64)
        self.single_action_space = gym.spaces.Box(*world.action_bounds(), (model.nu,), np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, n)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, n)
        self.autoreset_mode = gym.vector.AutoresetMode.DISABLED

    # ---------------------------------------------------------------- physics
    def _gather(self, i: int) -> None:
        """Row i's reading from its data (after a step or a reset)."""
        d, w, r = self.datas[i], self.world, self.reading
        r.qpos[i], r.qvel[i], r.xpos[i] = d.qpos, d.qvel, d.xpos
        r.trunk_xmat[i] = d.xmat[w.trunk]
        r.feet_xy[i] = d.geom_xpos[w.feet, :2]
        r.actuator_force[i] = d.actuator_force
        if r.cfrc_ext is not None:
            r.cfrc_ext[i] = d.cfrc_ext
        if self.task.reads_contacts:
            self.task.contacts.read(i, d)

    def _step_rows(self, rows: Sequence[int], ctrl: np.ndarray) -> None:
        models, datas, fs = self.models, self.datas, self.world.frame_skip
        if self.task.needs_peak or self.gait is not None:
            self._substep_rows(rows, ctrl)
        else:
            for i in rows:
                d = datas[i]
                d.ctrl[:] = ctrl[i]
                mujoco.mj_step(models[i], d, fs)
                mujoco.mj_rnePostConstraint(models[i], d)

    def _substep_rows(self, rows, ctrl: np.ndarray) -> None:
        """One physics step at a time: each actuated joint's top speed (and, in evaluation, the gait) sampled."""
        w, r = self.world, self.reading
        dofs = w.act_dofs
        for i in rows:
            d, m = self.datas[i], self.models[i]
            d.ctrl[:] = ctrl[i]
            peak = np.zeros(len(dofs))
            for _ in range(w.frame_skip):
                mujoco.mj_step(m, d)
                speeds = np.abs(d.qvel[dofs])
                np.maximum(peak, speeds, out=peak)
                if self.gait is not None:
                    self.gait.sample(i, d, float(speeds.max()) if len(speeds) else 0.0, m.opt.timestep,
                                     bool(self.task.memory.moving[i]))
            if r.step_peak is not None:
                r.step_peak[i] = peak
            mujoco.mj_rnePostConstraint(m, d)

    def _physics(self, ctrl: np.ndarray) -> None:
        if self._pool is None:
            self._step_rows(range(self.num_envs), ctrl)
        else:
            list(self._pool.map(self._step_rows, self._chunks, [ctrl] * self.threads))

    # ---------------------------------------------------------------- the vector env
    def step(self, actions):
        actions = np.asarray(actions)
        if actions.shape != (self.num_envs, self.world.model.nu):
            actions = actions.reshape(self.num_envs, self.world.model.nu)
        task, m = self.task, self.task.memory
        xy_before = self.reading.xpos[:, self.world.trunk, :2].copy()
        start = time.perf_counter()
        rand = task.randomize
        applied = actions.astype(np.float64)
        if rand.delayed.any():  # those rows' drives get the last step's action; this one waits a step
            late = applied.copy()
            applied[rand.delayed] = m.late_action[rand.delayed]
            m.late_action[:] = late
        rand.push(self.datas, self.rngs)
        self._physics(self.world.ctrl_of(applied))
        physics = time.perf_counter()
        for i in range(self.num_envs):  # in this thread: Python, which holds the GIL anyway
            self._gather(i)
        reward, terminated = task.step(actions, self.reading, xy_before, self.rngs)
        m.elapsed += 1
        truncated = m.elapsed >= self.max_steps
        m.returns += reward
        m.lengths += 1
        done = terminated | truncated
        if done.any():
            m.last_term_sums[done] = m.term_sums[done]
        self.last_obs = rand.noisy(task.observe(self.reading), self.rngs, slice(None))
        if self.timing is not None:
            self.timing["physics"] += physics - start
            self.timing["task"] += time.perf_counter() - physics
        return self.last_obs, reward, terminated, truncated, {}

    def reset(self, *, seed=None, options=None):
        mask = None if not options else options.get("reset_mask")
        rows = range(self.num_envs) if mask is None else np.flatnonzero(np.asarray(mask).reshape(-1))
        seeds = ([seed + i for i in range(self.num_envs)] if isinstance(seed, (int, np.integer)) else
                 list(seed) if seed is not None else [None] * self.num_envs)
        for i in rows:
            self.reset_row(int(i), seeds[i])
        return self.last_obs.copy(), {}

    def reset_row(self, i: int, seed: Optional[int] = None) -> np.ndarray:
        """Row i starts a new episode (or continues the position pending for it): its observation."""
        start = time.perf_counter()
        try:
            return self._reset_row(i, seed)
        finally:
            if self.timing is not None:
                self.timing["task"] += time.perf_counter() - start

    def _reset_row(self, i: int, seed: Optional[int]) -> np.ndarray:
        if self.pending is not None and self.pending[i] is not None:
            position, self.pending[i] = self.pending[i], None
            self.restore_row(i, position)
            return self.last_obs[i]
        task, m, d, model = self.task, self.task.memory, self.datas[i], self.models[i]
        if m.stepped[i]:  # judge the episode before the reset wipes it
            task.terrain.episode_ended(i, d.xpos[self.world.trunk, :2])
        if seed is not None:
            self.rngs[i] = seeding.np_random(int(seed))[0]
        rng = self.rngs[i]
        mujoco.mj_resetData(model, d)
        task.terrain.draw(i, rng, model)
        task.command.resample(i, rng)
        task.randomize.draw(i, rng, model)
        m.reset_row(i)
        task.ending[i], task.ending_body[i] = 0, None
        if self.gait is not None:
            self.gait.reset(i)
        w, s = self.world, self.noise
        d.qpos[:] = w.init_qpos + rng.uniform(low=-s, high=s, size=model.nq)
        d.qvel[:] = w.init_qvel + s * rng.standard_normal(model.nv)
        mujoco.mj_forward(model, d)
        self._gather(i)
        m.prev_feet_xy[i] = self.reading.feet_xy[i]
        self.last_obs[i] = task.randomize.noisy(task.observe(self.reading, slice(i, i + 1)), self.rngs, slice(i, i + 1))[0]
        return self.last_obs[i]

    # ---------------------------------------------------------------- positions (EnvState saves them)
    def row_position(self, i: int) -> dict:
        """What a bit-exact continuation of row i's episode needs (positions.py's format for one env)."""
        d, model, m = self.datas[i], self.models[i], self.task.memory
        physics = np.empty(mujoco.mj_stateSize(model, STATE))
        mujoco.mj_getState(model, d, physics, STATE)
        extra = {"memory": m.row(i), "terrain": self.task.terrain.row_state(i),
                 "command": self.task.command.row_state(i), "randomize": self.task.randomize.row_state(i),
                 "xpos": d.xpos.copy()}
        return {"env": {"np_random": self.rngs[i].bit_generator.state, "extra": extra,
                        "elapsed_steps": int(m.elapsed[i]), "episode": (float(m.returns[i]), int(m.lengths[i])),
                        "mujoco": physics},
                "obs": self.last_obs[i].copy()}

    def restore_row(self, i: int, position: dict) -> None:
        from ppo_torchrl.errors import ConfigError

        state, d, model = position["env"], self.datas[i], self.models[i]
        if "memory" not in state.get("extra", {}):
            raise ConfigError("the checkpoint's env positions were saved by the locomotion env before the rebuild; "
                              "resume it with that version, or start a run of its config")
        self.rngs[i].bit_generator.state = state["np_random"]
        if state["mujoco"].shape[0] != mujoco.mj_stateSize(model, STATE):
            raise ConfigError("the checkpoint's simulator state does not fit this env's model")
        mujoco.mj_setState(model, d, state["mujoco"], STATE)
        extra = state["extra"]
        self.task.terrain.set_row_state(i, extra["terrain"], model)
        self.task.command.set_row_state(i, extra["command"])
        self.task.randomize.set_row_state(i, extra.get("randomize"), model)
        mujoco.mj_forward(model, d)
        memory = dict(extra["memory"])
        self.task.memory.set_row(i, memory)
        d.xpos[:] = extra["xpos"]  # mj_step leaves them from its last physics step's start; the next step reads them
        self._gather(i)
        self.last_obs[i] = np.asarray(position["obs"])

    def positions(self) -> list:
        return [self.row_position(i) for i in range(self.num_envs)]

    # ---------------------------------------------------------------- what EnvState and evaluate read
    def episodes(self) -> tuple:
        m = self.task.memory
        return m.returns.copy(), m.lengths.copy()

    def metrics(self) -> List[dict]:
        return self.task.metrics()

    def observation_layout(self):
        return self.task.layout()

    def privileged_layout(self):
        """The privileged observation's layout (task.py): what policy.critic_obs=privileged gives the critic."""
        return self.task.privileged_layout()

    def privileged(self, rows=slice(None)) -> np.ndarray:
        """Rows `rows`' privileged observation now: after a step (the next one of each row) or a row's reset."""
        return self.task.privileged(self.reading, rows)

    @property
    def dt(self) -> float:
        return self.world.dt

    def render(self):
        """Row 0 from the `track` camera (world.py adds one where the model has none): an RGB array."""
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.models[0], self.height, self.width)
        self._renderer.update_scene(self.datas[0], camera="track")
        return self._renderer.render()

    def close(self, **kwargs):
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
