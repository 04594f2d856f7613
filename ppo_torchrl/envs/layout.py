"""The observation's layout: its named segments, in order, and how each one is scaled.

Why: one running normalization over the whole observation treats every element alike, and an element
that seldom changes in training settles at a tiny std. Go1's 20 terrain heights did (2-6 mm while the
curriculum showed it few steps), so a step of ~6 cm read as the clip and a 0.25 l step was never seen for
what it is (issue 59). Each env declares what its observation is made of; the normalizer applies it:

- `running`: the running statistics, (x - mean) / max(std, eps), clipped at env.transforms.obs_clip
  (proprioception: joint angles and speeds, whose spread training measures best);
- `fixed(offset, scale, clip)`: (x - offset) / scale, clipped at +-clip, numbers the env derives from its
  model (terrain heights, in the robot's leg length l): a step reads the same whatever training showed;
- `none`: as it is (0/1 contact flags, a clock's sin and cos: already in [-1, 1]).

An env that declares nothing (Gymnasium's MuJoCo envs) is one running segment over everything, as is a
checkpoint's statistics without a layout (a run saved before issue 59): the normalization every earlier
run trained and is evaluated with, bit for bit.

Who does what: the env declares its segments (`observation_layout()`; LeggedTask.layout for the legged env),
`ObservationNormalizer` (normalization.py) turns them into per-element vectors once (`vectors`) and keeps
the statistics; the layout travels with them (`to_state`, in a checkpoint's "obs") to evaluation and
export, which bakes the same vectors. So a change of one segment's treatment is the env's declaration
alone; a new kind of treatment is this file and the formula's own file (normalization.py).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

RUNNING, FIXED, NONE = "running", "fixed", "none"
TREATMENTS = (RUNNING, FIXED, NONE)
WHOLE = "observation"  # the one segment of an env that declares none
# The batch key of an env's privileged observation (policy.critic_obs=privileged: the critic's input, normalized with
# statistics of its own): an env declares it with `privileged_layout()` (envs_playground.py's tasks do)
PRIVILEGED = "privileged_observation"
# env.legged.obs_layout (config.py): whole, the default (one running segment: runs saved before the key), or the
# env's own segments (tasks/locomotion/task.py, LeggedTask.layout)
OBS_LAYOUTS = ("whole", "segments")
OBS_FRAMES = ("world", "heading")  # env.legged.obs_frame (config.py)


@dataclass(frozen=True)
class Segment:
    """`size` consecutive elements named `name`; `offset`, `scale` and `clip` are a fixed treatment's."""

    name: str
    size: int
    treatment: str = RUNNING
    offset: float = 0.0
    scale: float = 1.0
    clip: Optional[float] = None

    def __post_init__(self):
        if self.treatment not in TREATMENTS:
            raise ValueError(f"segment '{self.name}': treatment '{self.treatment}' is not one of {TREATMENTS}")
        if self.size < 0 or (self.treatment == FIXED and not self.scale > 0):
            raise ValueError(f"segment '{self.name}': size {self.size} and scale {self.scale} must be >= 0 and > 0")

    @staticmethod
    def running(name: str, size: int) -> "Segment":
        return Segment(name, size)

    @staticmethod
    def fixed(name: str, size: int, offset: float, scale: float, clip: Optional[float]) -> "Segment":
        return Segment(name, size, FIXED, float(offset), float(scale), None if clip is None else float(clip))

    @staticmethod
    def none(name: str, size: int) -> "Segment":
        return Segment(name, size, NONE)


@dataclass(frozen=True)
class ObservationLayout:
    """The observation's segments in order (module doc)."""

    segments: Tuple[Segment, ...]

    @classmethod
    def whole(cls, size: int) -> "ObservationLayout":
        """One running segment over everything: an env that declares none, a checkpoint saved without one."""
        return cls((Segment.running(WHOLE, size),))

    @property
    def size(self) -> int:
        return sum(s.size for s in self.segments)

    @property
    def all_running(self) -> bool:
        return all(s.treatment == RUNNING for s in self.segments)

    def where(self, name: str) -> slice:
        """The elements of segment `name`."""
        start = 0
        for s in self.segments:
            if s.name == name:
                return slice(start, start + s.size)
            start += s.size
        raise KeyError(name)

    def vectors(self, clip: Optional[float]) -> Optional[tuple]:
        """Per element, once: (running: bool, offset, scale, bound) with `clip` (env.transforms.obs_clip) as the
        running elements' bound and inf for no bound; None where every element is running (the normalizer then
        runs today's scalar formula, bit for bit)."""
        if self.all_running:
            return None
        parts = []
        for s in self.segments:
            bound = clip if s.treatment == RUNNING else s.clip if s.treatment == FIXED else None
            offset, scale = (s.offset, s.scale) if s.treatment == FIXED else (0.0, 1.0)
            parts.append((np.full(s.size, s.treatment == RUNNING), np.full(s.size, offset), np.full(s.size, scale),
                          np.full(s.size, np.inf if bound is None else float(bound))))
        return tuple(np.concatenate(column) for column in zip(*parts))

    def to_state(self) -> list:
        """Plain Python (a list of dicts of str, int, float), as checkpoints keep it."""
        return [dict(name=s.name, size=s.size, treatment=s.treatment, offset=s.offset, scale=s.scale, clip=s.clip)
                for s in self.segments]

    @classmethod
    def from_state(cls, state: Optional[list], size: int) -> "ObservationLayout":
        """What `to_state` made; None (statistics saved before layouts): one running segment of `size`."""
        if not state:
            return cls.whole(size)
        return cls(tuple(Segment(str(s["name"]), int(s["size"]), str(s["treatment"]), float(s.get("offset", 0.0)),
                                 float(s.get("scale", 1.0)), None if s.get("clip") is None else float(s["clip"]))
                         for s in state))

    def describe(self) -> str:
        def one(s):
            if s.treatment == FIXED:
                bound = "no clip" if s.clip is None else f"clip {s.clip:g}"
                return f"{s.name}[{s.size}] fixed ((x - {s.offset:.4g}) / {s.scale:.4g}, {bound})"
            return f"{s.name}[{s.size}] {s.treatment}"

        return ", ".join(one(s) for s in self.segments)


def layout_of(gym_env) -> ObservationLayout:
    """The layout a Gymnasium env declares (`observation_layout()` on its unwrapped env), else one running
    segment over its observation; ValueError when the declared one does not cover the observation."""
    size = int(gym_env.observation_space.shape[0])
    declare = getattr(gym_env.unwrapped, "observation_layout", None)
    layout = declare() if callable(declare) else ObservationLayout.whole(size)
    if layout.size != size:
        raise ValueError(f"the env's observation layout covers {layout.size} elements, its observation has {size}")
    return layout


def privileged_layout_of(gym_env) -> Optional[ObservationLayout]:
    """The layout of the privileged observation a Gymnasium env (or a batched one) declares (`privileged_layout()` on
    its unwrapped env, which returns None when it has none), else None."""
    declare = getattr(getattr(gym_env, "unwrapped", gym_env), "privileged_layout", None)
    return declare() if callable(declare) else None
