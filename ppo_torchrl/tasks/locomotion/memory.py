"""All of a legged batch's episode memory in one explicit state (MuJoCo Playground's `State.info`, as arrays over
the rows): what the reward terms, the observation and the time limit carry from one control step to the next, and
the episode's counters. A reset clears a row's part; a checkpoint dumps a row's part whole (`row` / `set_row`)."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np


@dataclass
class EpisodeMemory:
    prev_action: np.ndarray  # [N, nu] the last action (action rate)
    late_action: np.ndarray  # [N, nu] the action a delayed row's drives get at the next step (randomize.py)
    air_time: np.ndarray  # [N, F] s each foot has been off the ground (air time, long swing)
    prev_contact: np.ndarray  # [N, F] each foot's contact at the last control step
    prev_feet_xy: np.ndarray  # [N, F, 2] each foot's position then (foot slip)
    clock_steps: np.ndarray  # [N] control steps since the episode began: the trot clock's time
    stepped: np.ndarray  # [N] the row has stepped since its reset (its episode is judged at the next reset)
    moving: np.ndarray  # [N] its last control step went forward at MOVING_SPEED or more (gait)
    elapsed: np.ndarray  # [N] control steps this episode (the time limit)
    returns: np.ndarray  # [N] the episode's return so far (Gymnasium's RecordEpisodeStatistics' counter)
    lengths: np.ndarray  # [N]
    term_sums: np.ndarray  # [N, T] each reward term's sum over the episode so far (T: the task's terms)
    last_term_sums: np.ndarray  # [N, T] those of the row's last finished episode (logged)

    @staticmethod
    def zeros(n: int, nu: int, feet: int, terms: int) -> "EpisodeMemory":
        return EpisodeMemory(prev_action=np.zeros((n, nu)), late_action=np.zeros((n, nu)), air_time=np.zeros((n, feet)),
                             prev_contact=np.zeros((n, feet), bool), prev_feet_xy=np.zeros((n, feet, 2)),
                             clock_steps=np.zeros(n, np.int64), stepped=np.zeros(n, bool), moving=np.zeros(n, bool),
                             elapsed=np.zeros(n, np.int64), returns=np.zeros(n), lengths=np.zeros(n, np.int64),
                             term_sums=np.zeros((n, terms)), last_term_sums=np.full((n, terms), np.nan))

    KEPT = ("last_term_sums",)  # what a reset leaves as it is

    def reset_row(self, i: int) -> None:
        for f in fields(self):
            if f.name not in self.KEPT:
                getattr(self, f.name)[i] = 0

    def row(self, i: int) -> dict:
        return {f.name: np.array(getattr(self, f.name)[i]) for f in fields(self)}

    def set_row(self, i: int, state: dict) -> None:
        for f in fields(self):
            if f.name in state:
                getattr(self, f.name)[i] = state[f.name]
