"""The contact sensors of a legged batch: what each row's robot touches the terrain with, read once per control step
from the row's MuJoCo contacts (the last physics step's, as MuJoCo leaves them).

For each row: a flag per foot on the terrain, the number of non-foot geoms on it (the trunk, a thigh: the geom's
kind, world.py), the first terrain contact of a terminate_on_contact body, and, where the stumble term asks, a
flag per foot touching on a face more than 45 degrees from level (the step's riser; legged_gym's feet_stumble read
from the contact normal). A geom of the terrain is one of a body welded to the world (the floor, the step).
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from ppo_torchrl.tasks.locomotion.world import FOOT, GROUND, NON_FOOT

FACE_NORMAL_Z = math.cos(math.radians(45.0))


class Contacts:
    """Per row contact readings (module doc): `feet` [N, F] bool, `body` [N] int, `ending` [N] geom id or -1,
    `on_face` [N, F] bool (only when asked)."""

    def __init__(self, n: int, world, faces: bool = False):
        self.kind, self.foot_index, self.ending_geom = world.kind, world.foot_index, world.ending_geom
        self.any_ending = bool(world.ending_geom.any())
        self.faces = faces
        n_feet = len(world.feet)
        self.feet = np.zeros((n, n_feet), bool)
        self.body = np.zeros(n, np.int64)
        self.ending = np.full(n, -1, np.int64)
        self.on_face = np.zeros((n, n_feet), bool)

    def partners(self, data) -> tuple:
        """(the geoms touching the terrain, one per contact in contact order; those contacts' indices)."""
        geom = data.contact.geom
        if not len(geom):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        kinds = self.kind[geom]
        first, second = kinds[:, 0] == GROUND, kinds[:, 1] == GROUND
        which = np.flatnonzero(first | second)
        return np.where(first[which], geom[which, 1], geom[which, 0]), which

    def read(self, i: int, data) -> None:
        """Row i's readings from its data."""
        partners, which = self.partners(data)
        kinds = self.kind[partners]
        feet = self.feet[i]
        feet[:] = False
        feet[self.foot_index[partners[kinds == FOOT]]] = True
        self.body[i] = len(np.unique(partners[kinds == NON_FOOT]))
        if self.any_ending:
            hit = partners[self.ending_geom[partners]]
            self.ending[i] = hit[0] if len(hit) else -1
        if self.faces:
            face = self.on_face[i]
            face[:] = False
            normal_z = data.contact.frame[which, 2]
            sel = (kinds == FOOT) & (np.abs(normal_z) < FACE_NORMAL_Z)
            face[self.foot_index[partners[sel]]] = True


def ending_body(model, geom: int) -> Optional[str]:
    """The name of the body a terminate_on_contact geom belongs to (None for -1)."""
    return None if geom < 0 else model.body(model.geom_bodyid[geom]).name
