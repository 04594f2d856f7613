"""The terrain of a legged batch, behind one small protocol: where the ground is (`height_at(rows, xy)`, 2-D
points), how a row's episode draws it (`draw`), what an episode's end tells it (`episode_ended`), and what a
training run logs of it (`metrics`, under the keys `metric_keys` names). A terrain kind is one class here with these
methods.

`StepTerrain`: one box across each row's path (env.terrain: its height and distance drawn per episode from a
range that a success-driven curriculum widens, a band under the curriculum's level, a share of flat episodes),
each row with its own curriculum, as N envs of the locomotion env before the rebuild had (robots/terrain.py, gone
since: the same draws from the same RNG, so a row continues that env's stream). The step is moved in the row's own model
(`body_pos`, no recompile). Heights are read along the heading, the box being 100 m wide; success is the trunk
`success_margin` beyond the edge. A model that has no step gets one at build time (`add_step`, MjSpec: no model file
is edited), its box reaching below the floor, so any height from 0 to its depth is a solid step.
`terrain_checks`: env.terrain's values, checked before anything is built (envs.env_checks).
"""

from __future__ import annotations

from collections import deque
from typing import List

import mujoco
import numpy as np

from ppo_torchrl.errors import ConfigError

CURRICULUM_KEYS = ("env/terrain_level", "env/terrain_success")  # what a training run logs of a curriculum
STEP_BODY = "step"  # terrain models: the static body that holds the step's box geom
TERRAIN_STEP_KEYS = ("step_height", "step_height_range", "step_distance")
STEP_WIDTH = 100.0  # m across the path: it cannot be walked around
STEP_LENGTH = 20.0  # m along it: no episode walks off its far side


def add_step(spec, height: float, distance: float, depth: float, heading) -> None:
    """Adds the step (a body named `step` with one box geom) to a model being built (mujoco.MjSpec): its
    edge `distance` ahead of the origin along `heading`, its top at `height`, its box `depth` deep (the
    tallest step it can make), made of the floor's stuff: the contact type, affinity, friction, solver
    parameters and material of the world's first plane geom (MuJoCo's defaults where there is none).
    The terrain turns it to face the heading at reset (StepTerrain.draw)."""
    floor = next((g for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE), None)
    half = np.array([STEP_LENGTH / 2, STEP_WIDTH / 2, depth / 2])
    centre = (distance + half[0]) * np.asarray(heading, float)
    body = spec.worldbody.add_body(name=STEP_BODY, pos=[centre[0], centre[1], height - half[2]])
    geom = body.add_geom(name=STEP_BODY, type=mujoco.mjtGeom.mjGEOM_BOX, size=half, rgba=[0.45, 0.5, 0.55, 1])
    if floor is not None:
        geom.contype, geom.conaffinity, geom.condim = floor.contype, floor.conaffinity, floor.condim
        geom.friction, geom.material = floor.friction, floor.material
        geom.solref, geom.solimp, geom.priority = floor.solref, floor.solimp, floor.priority


class FlatTerrain:
    """The floor at z = 0 (a model without a step)."""

    has_step = False

    def __init__(self, n: int):
        self.n = n

    def height_at(self, rows, xy: np.ndarray) -> np.ndarray:
        return np.zeros(xy.shape[:-1])

    def draw(self, i: int, rng, model) -> None:
        pass

    def episode_ended(self, i: int, trunk_xy) -> None:
        pass

    def metrics(self) -> List[dict]:
        return []

    def metric_keys(self) -> List[str]:
        return []

    def row_state(self, i: int) -> dict:
        return {}

    def set_row_state(self, i: int, state: dict, model) -> None:
        pass


class StepTerrain:
    """One step per row (module doc)."""

    has_step = True

    def __init__(self, n: int, world, terrain: dict, evaluation: bool):
        model, self.n = world.model, n
        self.heading = world.heading
        self._side = np.array([-world.heading[1], world.heading[0]])
        self._body, self._geom = world.step_body, world.step_geom
        self._alpha = float(model.geom_rgba[self._geom, 3])
        self._half = model.geom_size[self._geom].copy()
        self._box_offset = model.geom_pos[self._geom].copy()
        self._pos0 = model.body_pos[self._body].copy()
        import mujoco

        data = mujoco.MjData(model)
        data.qpos[:] = world.init_qpos
        mujoco.mj_kinematics(model, data)
        self._start_along = self.along(data.xpos[world.trunk])
        # the model file's step (its box's axes along the world's): its top and near edge along the heading
        pos = self._pos0 + self._box_offset
        reach = abs(self.heading[0]) * self._half[0] + abs(self.heading[1]) * self._half[1]
        height0, edge0 = float(pos[2] + self._half[2]), self.along(pos) - float(reach)
        self.model_step = (height0, edge0 - self._start_along)
        self.success_margin = float(terrain.get("success_margin", 0.5))
        fixed = terrain.get("step_height")
        if evaluation and fixed is None:
            fixed = terrain.get("eval_step_height")
        self._fixed = None if fixed is None else float(fixed)
        span = terrain.get("step_height_range")
        self._range = None if span is None else (float(span[0]), float(span[1]))
        self.curriculum = bool(terrain.get("curriculum")) and self._fixed is None and not evaluation
        if self.curriculum and self._range is None:
            raise ConfigError("env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max]")
        distance = terrain.get("step_distance")
        self._distance = None if distance is None else (float(distance[0]), float(distance[1]))
        self._moves = self._fixed is not None or self._range is not None or self._distance is not None
        self._level_step = float(terrain.get("curriculum_step") or 0.02)
        self._threshold = float(terrain.get("curriculum_threshold") or 0.8)
        band = terrain.get("curriculum_band")
        self._band = None if band is None else float(band)
        share = terrain.get("curriculum_band_share")
        self._band_share = 1.0 if share is None else float(share)
        self._flat_share = 0.0 if evaluation else float(terrain.get("flat_share") or 0.0)
        down = terrain.get("curriculum_down_threshold")
        self._down = None if down is None else float(down)
        window = int(terrain.get("curriculum_window") or 20)
        depth = 2 * self._half[2]
        top = max([self._fixed or 0.0, *(self._range or ())])
        if top > depth:
            raise ConfigError(f"env.terrain: a step of {top} m is taller than the model's step box is deep ({depth} m)")
        self.height = np.full(n, height0)  # each row's step: its top (m) and its edge along the heading
        self.edge = np.full(n, edge0)
        self.level = np.full(n, self._range[0] if self._range else height0)  # curriculum: the range's top now
        self.flat_episode = np.zeros(n, bool)  # this episode's step was put at 0 by flat_share
        self.outcomes = [deque(maxlen=window) for _ in range(n)]
        self.recent = [deque(maxlen=window) for _ in range(n)]  # the same, kept across level changes (logged)

    def along(self, xy) -> np.ndarray:
        """Positions' coordinate along the heading ([..., 2 or 3] -> [...])."""
        xy = np.asarray(xy)
        return xy[..., 0] * self.heading[0] + xy[..., 1] * self.heading[1]

    def height_at(self, rows, xy: np.ndarray) -> np.ndarray:
        """The ground's height at points xy ([len(rows), ..., 2]) of rows `rows` (a slice or index array)."""
        extra = (slice(None),) + (None,) * (xy.ndim - 2)
        return np.where(self.along(xy) >= self.edge[rows][extra], self.height[rows][extra], 0.0)

    def crossed(self, i: int, trunk_xy) -> bool:
        return bool(self.along(trunk_xy) >= self.edge[i] + self.success_margin)

    def place(self, i: int, height: float, distance: float, model) -> None:
        edge = self._start_along + distance
        along = edge + self._half[0] - self._box_offset[0]  # the box's own x is the heading
        xy = along * self.heading + (self._side @ self._pos0[:2]) * self._side
        model.body_pos[self._body] = [xy[0], xy[1], height - self._half[2] - self._box_offset[2]]
        # a step of height 0 is not drawn (its top in the floor's plane flickers on film); no contact reads colour
        model.geom_rgba[self._geom, 3] = self._alpha if height > 0 else 0.0
        self.height[i], self.edge[i] = height, edge

    def draw(self, i: int, rng, model) -> None:
        """Row i's step for its next episode, from its own RNG (the order of draws of robots/terrain.py)."""
        if not self._moves:
            return
        self.flat_episode[i] = (self._fixed is None and self._range is not None
                                and self._flat_share > 0 and rng.uniform() < self._flat_share)
        if self._fixed is not None:
            height = self._fixed
        elif self.flat_episode[i]:
            height = 0.0
        elif self._range is not None:
            low, high = self._range
            if self.curriculum:
                if self._band is not None and (self._band_share >= 1 or rng.uniform() < self._band_share):
                    low = max(low, self.level[i] - self._band)
                high = self.level[i]
            height = float(rng.uniform(low, high))
        else:
            height = self.model_step[0]
        distance = float(rng.uniform(*self._distance)) if self._distance else self.model_step[1]
        self.place(i, height, distance, model)

    def episode_ended(self, i: int, trunk_xy) -> None:
        """Row i's episode is over (judged before its reset): the curriculum takes its outcome."""
        if self.curriculum and not self.flat_episode[i]:
            self._record(i, self.crossed(i, trunk_xy))

    def _record(self, i: int, success: bool) -> None:
        outcomes = self.outcomes[i]
        outcomes.append(bool(success))
        self.recent[i].append(bool(success))
        if len(outcomes) < outcomes.maxlen:
            return
        rate = np.mean(outcomes)
        if rate >= self._threshold:
            self.level[i] = min(self.level[i] + self._level_step, self._range[1])
            outcomes.clear()
        elif self._down is not None and rate <= self._down:
            self.level[i] = max(self.level[i] - self._level_step, self._range[0])
            outcomes.clear()

    def metrics(self) -> List[dict]:
        """Per row, what a training run logs of its curriculum ([] without one, evaluation included)."""
        if not self.curriculum:
            return []
        level, success = CURRICULUM_KEYS
        return [{level: float(self.level[i]), success: float(np.mean(self.recent[i])) if self.recent[i] else 0.0}
                for i in range(self.n)]

    def metric_keys(self) -> List[str]:
        """The keys `metrics` gives (metrics.csv's columns of the terrain)."""
        return list(CURRICULUM_KEYS) if self.curriculum else []

    def row_state(self, i: int) -> dict:
        return {"step_height": float(self.height[i]), "step_edge": float(self.edge[i]), "level": float(self.level[i]),
                "flat_episode": bool(self.flat_episode[i]), "outcomes": list(self.outcomes[i]),
                "recent": list(self.recent[i])}

    def set_row_state(self, i: int, state: dict, model) -> None:
        if "step_height" not in state:
            return
        self.place(i, state["step_height"], state["step_edge"] - self._start_along, model)
        self.level[i], self.flat_episode[i] = state["level"], state.get("flat_episode", False)
        self.outcomes[i].clear()
        self.outcomes[i].extend(state["outcomes"])
        self.recent[i].clear()
        self.recent[i].extend(state.get("recent", state["outcomes"]))


def make_terrain(n: int, world, terrain: dict, evaluation: bool):
    """The terrain kind of a world: its step when the model has (or was given) one, else the floor."""
    asked = [k for k in ("step_height", "step_height_range", "step_distance", "eval_step_height")
             if terrain.get(k) is not None] + (["curriculum"] if terrain.get("curriculum") else [])
    if world.step_body > 0:
        return StepTerrain(n, world, terrain, evaluation)
    if asked:
        raise ConfigError(f"env.terrain.{asked[0]} needs a model with a body named 'step' holding the step's box")
    return FlatTerrain(n)


def ground_under(terrain, rows, xy: np.ndarray) -> np.ndarray:
    """The ground's height under one point per row ([len(rows), 2] -> [len(rows)])."""
    return terrain.height_at(rows, xy[:, None, :])[:, 0]


def terrain_checks(terrain) -> list:
    """env.terrain: heights >= 0, [min, max] ranges with min <= max, a threshold in (0, 1], counts >= 1."""
    if terrain is None:
        return []

    def span(key, low_ok):
        value = terrain.get(key)
        if value is None:
            return True, ""
        value = list(value)
        ok = len(value) == 2 and low_ok(value[0]) and value[0] <= value[1]
        floor = "0 <= min" if key == "step_height_range" else "0 < min"
        return ok, f"env.terrain.{key}={value} must be [min, max] with {floor} <= max (m)"

    height, eval_height = terrain.get("step_height"), terrain.get("eval_step_height")
    return [
        (height is None or height >= 0, f"env.terrain.step_height={height} must be >= 0 (m)"),
        (eval_height is None or eval_height >= 0, f"env.terrain.eval_step_height={eval_height} must be >= 0 (m)"),
        span("step_height_range", lambda low: low >= 0),
        span("step_distance", lambda low: low > 0),
        (0 < terrain.curriculum_threshold <= 1,
         f"env.terrain.curriculum_threshold={terrain.curriculum_threshold} must be in (0, 1]: a success rate"),
        (terrain.curriculum_window >= 1, f"env.terrain.curriculum_window={terrain.curriculum_window} must be >= 1"),
        (terrain.curriculum_step > 0, f"env.terrain.curriculum_step={terrain.curriculum_step} must be > 0 (m)"),
        (terrain.curriculum_down_threshold is None or 0 <= terrain.curriculum_down_threshold < terrain.curriculum_threshold,
         f"env.terrain.curriculum_down_threshold={terrain.curriculum_down_threshold} must be in "
         f"[0, curriculum_threshold={terrain.curriculum_threshold}): a success rate"),
        (terrain.get("curriculum_band") is None or terrain.curriculum_band > 0,
         f"env.terrain.curriculum_band={terrain.get('curriculum_band')} must be > 0 (m) or null"),
        (0 <= terrain.curriculum_band_share <= 1,
         f"env.terrain.curriculum_band_share={terrain.curriculum_band_share} must be in [0, 1]: a share of episodes"),
        (0 <= terrain.flat_share <= 1, f"env.terrain.flat_share={terrain.flat_share} must be in [0, 1]: a share of episodes"),
        (not terrain.curriculum or terrain.step_height_range is not None,
         "env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max] to widen"),
        (terrain.success_margin >= 0, f"env.terrain.success_margin={terrain.success_margin} must be >= 0 (m)"),
        (terrain.height_samples >= 0, f"env.terrain.height_samples={terrain.height_samples} must be >= 0"),
        (terrain.height_sample_spacing > 0,
         f"env.terrain.height_sample_spacing={terrain.height_sample_spacing} must be > 0 (m)"),
    ]
