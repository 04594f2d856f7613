"""Contacts of a legged robot with the ground and the step: which geoms are feet, which bodies are not,
each foot's corner, and which contact ends an episode (`terminate_on_contact`, legged_gym's).

A mixin of `LocomotionEnv` (robots/env.py), which calls `_set_up_contacts` and
`_set_up_contact_termination` once its model is built and reads the contacts once per control step
(`_now`). A non-foot body is a robot body that holds no foot geom: the trunk, a thigh; not the shank
that carries the foot (its capsule ends inside the foot sphere and touches whenever the foot sinks a
millimetre into the ground).
"""

from __future__ import annotations

import math
from typing import Optional

import mujoco
import numpy as np

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.robots.gait import CORNERS

# A foot's contact whose normal is more than 45 degrees from the vertical meets a face nearer upright than level: the
# step's riser, or its edge met low (a stumble: legged_gym's feet_stumble, read from the contact's geometry, not a force)
FACE_NORMAL_Z = math.cos(math.radians(45.0))


class FootContacts:
    """The feet, the non-foot bodies and the contacts that end an episode (module doc)."""

    _now = None  # within step: its one reading of the contacts after the control step (_read_contacts)

    def _set_up_contacts(self, names, derived: Optional[list] = None) -> None:
        """The feet: the geoms named in env.locomotion.foot_geoms, else `derived` (the feet of a robot read from
        its model, robots/model.py), else the geoms whose name holds 'foot', else the geoms of childless bodies."""
        model = self.model
        root = model.body_rootid[self._body_id]
        robot = [g for g in range(model.ngeom) if model.body_rootid[model.geom_bodyid[g]] == root]
        if names:
            missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n) < 0]
            if missing:
                raise ConfigError(f"env.locomotion.foot_geoms: {', '.join(missing)} is not a geom of the model")
            feet = [model.geom(n).id for n in names]
        elif derived:
            feet = list(derived)
        else:
            feet = [g for g in robot if "foot" in model.geom(g).name.lower()]
            if not feet:  # the geoms of the bodies that have no child body
                parents = set(model.body_parentid[1:].tolist())
                feet = [g for g in robot if model.geom_bodyid[g] not in parents]
        self.feet = np.array(feet, dtype=np.int64)
        # 1 ground (static), 2 foot, 3 a geom of a robot body that holds no foot (a "non-foot body":
        # the trunk, a thigh); 0 the rest, such as the shank capsule that ends inside the foot sphere.
        self._kind = np.zeros(model.ngeom, np.int8)
        self._kind[model.body_weldid[model.geom_bodyid] == 0] = 1
        foot_bodies = set(model.geom_bodyid[self.feet].tolist())
        self._kind[[g for g in robot if model.geom_bodyid[g] not in foot_bodies]] = 3
        self._kind[self.feet] = 2
        self._kinds = self._kind.tolist()  # the per-step lookups, without arrays
        self._foot_of = {geom: i for i, geom in enumerate(self.feet.tolist())}  # a foot geom's place in self.feet
        self._forces = np.empty_like(self.data.cfrc_ext)  # contact_cost's buffer
        self.foot_corners = self._corners()
        # an unnamed foot geom (ANYmal B's, A1's) goes by its corner, else by its place
        self.foot_names = [model.geom(g).name or (self.foot_corners[i] if self.foot_corners else f"foot {i}")
                           for i, g in enumerate(self.feet)]

    def _corners(self) -> Optional[list]:
        """Each foot's corner (CORNERS: left or right of the feet's centre, ahead of it along the heading or
        behind) in the model's initial pose, for a robot with four feet, one at each corner; else None."""
        if len(self.feet) != 4:
            return None
        xy = self.data.geom_xpos[self.feet, :2] - self.data.geom_xpos[self.feet, :2].mean(axis=0)
        ahead, left = xy @ self.heading, xy @ np.array([-self.heading[1], self.heading[0]])
        corners = [("L" if y > 0 else "R") + ("F" if x > 0 else "H") for x, y in zip(ahead, left)]
        return corners if sorted(corners) == sorted(CORNERS) else None

    def _set_up_contact_termination(self, names) -> None:
        model = self.model
        missing = [n for n in names if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, n) < 0]
        if missing:
            raise ConfigError(f"env.locomotion.terminate_on_contact: {', '.join(missing)} is not a body of the model")
        self._ending_geom = np.zeros(model.ngeom, bool)  # geoms whose touching the ground or the step ends an episode
        for name in names:
            self._ending_geom[model.geom_bodyid == model.body(name).id] = True
        self._ending_geom &= self._kind != 1
        self._ends_on_contact = bool(self._ending_geom.any())

    def touches_ground(self) -> bool:
        """A geom of a terminate_on_contact body touches the ground or the step."""
        return self._ending_contact() is not None

    def _ending_contact(self) -> Optional[str]:
        """The terminate_on_contact body that touches the ground or the step (the first geom's), or None."""
        if not self._ends_on_contact:
            return None
        partners = self._now[0] if self._now is not None else self._ground_partners()
        ending = partners[self._ending_geom[partners]]
        return self.model.body(self.model.geom_bodyid[ending[0]]).name if len(ending) else None


    def _ground_partners(self) -> np.ndarray:
        """The geoms in contact with the ground or the step (one entry per contact, in contact order)."""
        kinds = self._kinds  # a handful of contacts: Python over their list beats numpy's per-call cost
        return np.array([b if kinds[a] == 1 else a for a, b in self.data.contact.geom.tolist()
                         if kinds[a] == 1 or kinds[b] == 1], np.int64)

    def ground_contacts(self) -> tuple:
        """(the geoms touching the ground or the step, each one's kind: 2 a foot, 0 another geom of a foot's body,
        3 a geom of a body that holds no foot), as the simulator stands now: one reading, for a gait's diagnosis."""
        partners = self._ground_partners()
        return partners, self._kind[partners]

    def feet_on_a_face(self) -> np.ndarray:
        """A flag per foot (in `foot_names` order) touching the ground or the step on a face nearer upright than level
        (FACE_NORMAL_Z), as the simulator stands now."""
        flags, kinds, contact = np.zeros(len(self.feet), bool), self._kinds, self.data.contact
        for (a, b), normal_z in zip(contact.geom.tolist(), contact.frame[:, 2].tolist()):
            foot = b if kinds[a] == 1 else a if kinds[b] == 1 else None
            if foot is not None and kinds[foot] == 2 and abs(normal_z) < FACE_NORMAL_Z:
                flags[self._foot_of[foot]] = True
        return flags

    def _read_contacts(self) -> tuple:
        """(the geoms touching the ground or the step, a ground-contact flag per foot, the number of
        geoms of non-foot bodies among them), as the simulator stands now."""
        feet, body = np.zeros(len(self.feet), bool), set()
        partners = self._ground_partners()
        for geom in partners.tolist():
            kind = self._kinds[geom]
            if kind == 2:
                feet[self._foot_of[geom]] = True
            elif kind == 3:
                body.add(geom)
        return partners, feet, len(body)

    def _contacts(self) -> tuple:
        """(a ground-contact flag per foot, the number of geoms of non-foot bodies touching the ground):
        within `step`, its one reading after the control step; elsewhere read now."""
        _, feet, body = self._now if self._now is not None else self._read_contacts()
        return feet, body


    def feet_on_ground(self) -> np.ndarray:
        """A ground-contact flag per foot (in `foot_names` order), as the simulator stands now."""
        return self._contacts()[0]
