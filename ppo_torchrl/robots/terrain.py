"""The terrain of a step env: one box across the robot's path, its height and distance drawn per
episode, from a range that a success-driven curriculum widens (or, with `curriculum_band`, a band
just under the curriculum's level that it raises, for a `curriculum_band_share` of the episodes);
`flat_share` of the training episodes on flat ground.

The step is a body named `step` holding one box geom: a model that has none gets one at build time
(`add_step`, MjSpec: no model file is edited). It is moved by `model.body_pos` at reset (no
recompile; moving a geom of the world body instead leaves MuJoCo's collision bounding volumes stale).
Its box reaches below the floor, so any height from 0 to the box's depth is a solid step. Distances
(the edge, the success line, the height samples) run along the heading, and the box is turned to face
it, so a robot built facing -x or +y meets the step ahead of it.

`StepTerrain` is a mixin of `LocomotionEnv` (robots/env.py): it reads the env's `model`, `data`,
`heading`, `_body_id` and `np_random`.
"""

from __future__ import annotations

import math
from collections import deque

import mujoco
import numpy as np

from ppo_torchrl.errors import ConfigError

STEP_BODY = "step"  # terrain models: the static body that holds the step's box geom
TERRAIN_STEP_KEYS = ("step_height", "step_height_range", "step_distance")
STEP_WIDTH = 100.0  # m across the path: it cannot be walked around
STEP_LENGTH = 20.0  # m along it: no episode walks off its far side


def add_step(spec, height: float, distance: float, depth: float, heading) -> None:
    """Adds the step (a body named `step` with one box geom) to a model being built (mujoco.MjSpec): its
    edge `distance` ahead of the origin along `heading`, its top at `height`, its box `depth` deep (the
    tallest step it can make), made of the floor's stuff: the contact type, affinity, friction, solver
    parameters and material of the world's first plane geom (MuJoCo's defaults where there is none).
    The terrain turns it to face the heading at reset (StepTerrain._set_up_terrain)."""
    floor = next((g for g in spec.worldbody.geoms if g.type == mujoco.mjtGeom.mjGEOM_PLANE), None)
    half = np.array([STEP_LENGTH / 2, STEP_WIDTH / 2, depth / 2])
    centre = (distance + half[0]) * np.asarray(heading, float)
    body = spec.worldbody.add_body(name=STEP_BODY, pos=[centre[0], centre[1], height - half[2]])
    geom = body.add_geom(name=STEP_BODY, type=mujoco.mjtGeom.mjGEOM_BOX, size=half, rgba=[0.45, 0.5, 0.55, 1])
    if floor is not None:
        geom.contype, geom.conaffinity, geom.condim = floor.contype, floor.conaffinity, floor.condim
        geom.friction, geom.material = floor.friction, floor.material
        geom.solref, geom.solimp, geom.priority = floor.solref, floor.solimp, floor.priority


class StepTerrain:
    """The step, its curriculum and the success line (module doc)."""

    def _set_up_terrain(self, terrain: dict, evaluation: bool) -> None:
        model = self.model
        self.observe_contacts = bool(terrain.get("observe_contacts", False))
        self.height_samples = int(terrain.get("height_samples") or 0)
        self._sample_spacing = float(terrain.get("height_sample_spacing") or 0.1)
        self._sample_offsets = self._sample_spacing * np.arange(self.height_samples)  # from main_body, along the heading
        self._step_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, STEP_BODY)
        asked = [k for k in TERRAIN_STEP_KEYS + ("eval_step_height",) if terrain.get(k) is not None]
        if terrain.get("curriculum"):
            asked.append("curriculum")
        self.has_step = self._step_id > 0
        if asked and not self.has_step:
            raise ConfigError(f"env.terrain.{asked[0]} needs a model with a body named '{STEP_BODY}' holding the step's "
                              "box: env=legged adds one to any robot (or env=quadruped_step for the in-house quadruped)")
        self.success_margin = float(terrain.get("success_margin", 0.5))
        if not self.has_step:
            return
        geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == self._step_id]
        if len(geoms) != 1 or model.geom_type[geoms[0]] != mujoco.mjtGeom.mjGEOM_BOX:
            raise ConfigError(f"the model's body '{STEP_BODY}' must hold one box geom (the step)")
        g = geoms[0]
        self._step_geom, self._step_alpha = g, float(model.geom_rgba[g, 3])
        self._half = model.geom_size[g].copy()  # the box's half sizes
        self._box_offset = model.geom_pos[g].copy()
        # Distances run along the heading: the step's edge, the success line and the height samples
        # are coordinates on that ground axis (world x for heading x).
        self._start_along = self._along(self.data.xpos[self._body_id])
        self._step_pos0 = model.body_pos[self._step_id].copy()
        self.step_height, self.step_edge = self._read_step()
        self.model_step = (self.step_height, self.step_edge - self._start_along)  # as the model file has it
        # The step box turned so that its own x runs along the heading (its extent to the side stays
        # what the file gives, 100 m in quadruped_step.xml), and moved along the heading from then on.
        half_angle = 0.5 * math.atan2(self.heading[1], self.heading[0])
        model.body_quat[self._step_id] = [math.cos(half_angle), 0.0, 0.0, math.sin(half_angle)]
        self._side = np.array([-self.heading[1], self.heading[0]])
        fixed = terrain.get("step_height")
        if evaluation and fixed is None:
            fixed = terrain.get("eval_step_height")
        self._fixed_height = None if fixed is None else float(fixed)
        span = terrain.get("step_height_range")
        self._height_range = None if span is None else (float(span[0]), float(span[1]))
        self._curriculum = bool(terrain.get("curriculum")) and self._fixed_height is None and not evaluation
        if self._curriculum and self._height_range is None:
            raise ConfigError("env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max]")
        distance = terrain.get("step_distance")
        self._distance_range = None if distance is None else (float(distance[0]), float(distance[1]))
        # Without any of these the step stays exactly where the model file puts it.
        self._moves_step = (self._fixed_height is not None or self._height_range is not None
                            or self._distance_range is not None)
        self.level = self._height_range[0] if self._height_range else self.step_height  # curriculum: the range's top now
        self._level_step = float(terrain.get("curriculum_step") or 0.02)
        self._threshold = float(terrain.get("curriculum_threshold") or 0.8)
        band = terrain.get("curriculum_band")
        self._band = None if band is None else float(band)
        share = terrain.get("curriculum_band_share")
        self._band_share = 1.0 if share is None else float(share)
        self._flat_share = 0.0 if evaluation else float(terrain.get("flat_share") or 0.0)
        self._flat_episode = False  # this episode's step was put at 0 by flat_share (not a curriculum outcome)
        down = terrain.get("curriculum_down_threshold")
        self._down_threshold = None if down is None else float(down)
        self.outcomes = deque(maxlen=int(terrain.get("curriculum_window") or 20))
        self.recent = deque(maxlen=self.outcomes.maxlen)  # the same outcomes, kept across level changes (logged)
        depth = 2 * self._half[2]
        top = max([self._fixed_height or 0.0, *(self._height_range or ())])
        if top > depth:
            raise ConfigError(f"env.terrain: a step of {top} m is taller than the model's step box is deep ({depth} m)")

    def _along(self, xyz) -> float:
        """A world position's coordinate along the heading (x for heading x)."""
        return float(xyz[0] * self.heading[0] + xyz[1] * self.heading[1])

    def _read_step(self) -> tuple:
        """The model file's step (a box with its axes along the world's): its top and near edge along the heading."""
        pos = self.model.body_pos[self._step_id] + self._box_offset
        reach = abs(self.heading[0]) * self._half[0] + abs(self.heading[1]) * self._half[1]
        return float(pos[2] + self._half[2]), self._along(pos) - float(reach)

    def _place_step(self, height: float, distance: float) -> None:
        edge = self._start_along + distance
        # the box's own x is the heading (body_quat), so its offset in the body moves the box along it
        along = edge + self._half[0] - self._box_offset[0]
        xy = along * self.heading + (self._side @ self._step_pos0[:2]) * self._side
        self.model.body_pos[self._step_id] = [xy[0], xy[1], height - self._half[2] - self._box_offset[2]]
        # a step of height 0 is not drawn: its top in the floor's plane filmed as flickering dark patches
        # (z-fighting); MuJoCo does not draw a transparent geom, and no contact or force reads the colour
        self.model.geom_rgba[self._step_geom, 3] = self._step_alpha if height > 0 else 0.0
        self.step_height, self.step_edge = height, edge

    def _draw_step(self) -> None:
        rng = self.np_random
        # (share 0 draws nothing extra, so runs without the knob keep their random stream)
        self._flat_episode = (self._fixed_height is None and self._height_range is not None
                              and self._flat_share > 0 and rng.uniform() < self._flat_share)
        if self._fixed_height is not None:
            height = self._fixed_height
        elif self._flat_episode:
            height = 0.0
        elif self._height_range is not None:
            low, high = self._height_range
            if self._curriculum:
                # (share 1 draws nothing extra, so runs without the knob keep their random stream)
                if self._band is not None and (self._band_share >= 1 or rng.uniform() < self._band_share):
                    low = max(low, self.level - self._band)
                high = self.level
            height = float(rng.uniform(low, high))
        else:
            height = self.model_step[0]
        distance = float(rng.uniform(*self._distance_range)) if self._distance_range else self.model_step[1]
        self._place_step(height, distance)

    def _record_outcome(self, success: bool) -> None:
        """The curriculum: widen [min, level] by curriculum_step once the success rate of a full window
        reaches the threshold; narrow it by as much when it falls to the down threshold (if set)."""
        self.outcomes.append(bool(success))
        self.recent.append(bool(success))
        if len(self.outcomes) < self.outcomes.maxlen:
            return
        rate = np.mean(self.outcomes)
        if rate >= self._threshold:
            self.level = min(self.level + self._level_step, self._height_range[1])
            self.outcomes.clear()
        elif self._down_threshold is not None and rate <= self._down_threshold:
            self.level = max(self.level - self._level_step, self._height_range[0])
            self.outcomes.clear()

    def terrain_metrics(self) -> dict:
        """What a training run logs of its curriculum: the top of the height range now (m) and the share of
        the last curriculum_window episodes that crossed; {} without a curriculum (evaluation included)."""
        if not (self.has_step and self._curriculum):
            return {}
        return {"env/terrain_level": self.level, "env/terrain_success": float(np.mean(self.recent)) if self.recent else 0.0}

    def crossed(self) -> bool:
        """Success on a step env: the main body is success_margin beyond the step's edge."""
        return self._along(self.data.xpos[self._body_id]) >= self.step_edge + self.success_margin

    def _ground_under_body(self) -> float:
        """The terrain's height under main_body (m)."""
        if not self.has_step:  # terrain_height for one point, without an array (once or twice a step)
            return 0.0
        return float(self.step_height) if self._along(self.data.xpos[self._body_id]) >= self.step_edge else 0.0

    def terrain_height(self, x: np.ndarray) -> np.ndarray:
        """Ground height at coordinate x along the heading (the step's top beyond its edge, else the floor at 0)."""
        if not self.has_step:
            return np.zeros_like(x)
        return np.where(x >= self.step_edge, self.step_height, 0.0)


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
