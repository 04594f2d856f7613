"""Randomized physics for a legged batch (config.py, RandomizeConfig): each row's world drawn at its reset from its own
RNG, after the terrain and the command, and applied to the row's own model: every geom's friction, the trunk's mass
and inertia and its centre of mass, every servo's gains (motor strength); during the episode pushes (a ground velocity
added to the trunk at drawn intervals), noise on what the policy observes, and, for a share of episodes, the actions
reaching the drives one control step late. Each row's draw is recorded (`draws[i]`, in the episode's outcome) and can
be replayed (`fix`: an evaluation at the randomization's extremes); an evaluation env is otherwise the nominal world. With the defaults nothing is drawn, so a recipe
without randomization keeps its RNG streams.
"""

from __future__ import annotations

from typing import Optional

import mujoco
import numpy as np

NOISE = {"height_attitude": 0.02, "joint_angle": 0.03, "linear": 0.05, "angular": 0.04, "joint_speed": 0.3}


class Randomization:
    def __init__(self, n: int, world, randomize: Optional[dict], evaluation: bool):
        """evaluation: the nominal world (nothing drawn, no pushes, no noise, no delay) unless a draw is fixed."""
        r = {} if evaluation else dict(randomize or {})
        self.n, self.world = n, world
        self.friction = tuple(r.get("friction", (1.0, 1.0)))
        self.trunk_mass = tuple(r.get("trunk_mass", (1.0, 1.0)))
        self.com = float(r.get("com", 0.0))
        self.strength = tuple(r.get("strength", (1.0, 1.0)))
        self.push_speed = float(r.get("push_speed", 0.0))
        self.push_interval = tuple(r.get("push_interval", (1.0, 14.0)))
        self.obs_noise = float(r.get("obs_noise", 0.0))
        self.delay_share = float(r.get("delay_share", 0.0))
        self.active = (self.friction != (1.0, 1.0) or self.trunk_mass != (1.0, 1.0) or self.com > 0
                       or self.strength != (1.0, 1.0) or self.delay_share > 0)
        model = world.model
        self._friction0 = model.geom_friction.copy()
        self._mass0, self._inertia0 = float(model.body_mass[world.trunk]), model.body_inertia[world.trunk].copy()
        self._ipos0 = model.body_ipos[world.trunk].copy()
        servo = model.actuator_biastype == mujoco.mjtBias.mjBIAS_AFFINE
        self._servo = servo
        self._gain0, self._bias0 = model.actuator_gainprm[:, 0].copy(), model.actuator_biasprm[:, 1:3].copy()
        self.draws = [dict() for _ in range(n)]
        self.fixed: list = [None] * n  # a draw to replay at the row's next resets (evaluate)
        self.delayed = np.zeros(n, bool)
        self.push_countdown = np.full(n, -1, np.int64)
        speed, time = world.units
        self.noise_scale = self._noise_scale(speed, 1.0 / time) * self.obs_noise

    def _noise_scale(self, speed: float, rate: float) -> np.ndarray:
        """Per element of Ant-v5's observation (qpos[2:], qvel): the noise at level 1 (NOISE)."""
        model = self.world.model
        nq, nv = model.nq, model.nv
        scale = np.zeros(nq - 2 + nv)
        scale[:5] = NOISE["height_attitude"]  # the free joint's z and quaternion
        scale[5:nq - 2] = NOISE["joint_angle"]
        scale[nq - 2:nq - 2 + 3] = NOISE["linear"] * speed
        scale[nq - 2 + 3:nq - 2 + 6] = NOISE["angular"] * rate
        scale[nq - 2 + 6:] = NOISE["joint_speed"] * rate
        return scale

    def fix(self, i: int, draw: Optional[dict]) -> None:
        """Replay `draw` (a recorded one, or extremes) at row i's resets instead of drawing (None: draw again)."""
        self.fixed[i] = draw

    def draw(self, i: int, rng, model) -> None:
        """Row i's world for its next episode, applied to its model (the draws' order is fixed: see the module doc)."""
        if not (self.active or self.push_speed > 0 or self.fixed[i] is not None):
            return
        d = self.fixed[i] if self.fixed[i] is not None else {
            "friction": float(rng.uniform(*self.friction)), "trunk_mass": float(rng.uniform(*self.trunk_mass)),
            "com": rng.uniform(-self.com, self.com, 3).tolist() if self.com > 0 else [0.0, 0.0, 0.0],
            "strength": float(rng.uniform(*self.strength)),
            "delayed": bool(self.delay_share > 0 and rng.uniform() < self.delay_share)}
        self.draws[i] = dict(d)
        trunk = self.world.trunk
        model.geom_friction[:] = self._friction0 * d["friction"]
        model.body_mass[trunk] = self._mass0 * d["trunk_mass"]
        model.body_inertia[trunk] = self._inertia0 * d["trunk_mass"]
        model.body_ipos[trunk] = self._ipos0 + np.asarray(d["com"])
        s = self._servo
        model.actuator_gainprm[s, 0] = self._gain0[s] * d["strength"]
        model.actuator_biasprm[s, 1:3] = self._bias0[s] * d["strength"]
        self.delayed[i] = d["delayed"]
        self.push_countdown[i] = self._interval(rng) if self.push_speed > 0 and rng is not None else -1

    def _interval(self, rng) -> int:
        return max(1, round(rng.uniform(*self.push_interval) / self.world.dt))

    def push(self, datas, rngs) -> None:
        """After a control step: rows whose time has come are pushed (a ground velocity added to the trunk)."""
        if self.push_speed <= 0:
            return
        self.push_countdown -= 1
        for i in np.flatnonzero(self.push_countdown == 0):
            rng = rngs[i]
            datas[i].qvel[0:2] += rng.uniform(-self.push_speed, self.push_speed, 2)
            self.push_countdown[i] = self._interval(rng)

    def noisy(self, obs: np.ndarray, rngs, rows) -> np.ndarray:
        """What the policy sees: the observation with noise on its first (Ant-v5's) part, from each row's RNG."""
        if self.obs_noise <= 0:
            return obs
        k = len(self.noise_scale)
        out = obs.copy()
        for j, i in enumerate(range(self.n)[rows]):
            out[j, :k] += rngs[i].uniform(-1.0, 1.0, k) * self.noise_scale
        return out

    def row_state(self, i: int) -> dict:
        return {"draw": dict(self.draws[i]), "delayed": bool(self.delayed[i]),
                "push_countdown": int(self.push_countdown[i])}

    def set_row_state(self, i: int, state: dict, model) -> None:
        if not state or not state.get("draw"):
            return
        fixed, self.fixed[i] = self.fixed[i], state["draw"]
        self.draw(i, None, model)  # the recorded draw, applied again
        self.fixed[i] = fixed
        self.push_countdown[i] = state["push_countdown"]
