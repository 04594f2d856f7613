"""A run records the robot model it trained on: the sha256 of the compiled model (MuJoCo's binary MJB of
`env.xml_file` as MuJoCo compiles it: every mass, inertia, size, joint range, actuator gain and mesh vertex,
whatever files it includes) in each checkpoint (`model`). `resume=` and `evaluate` compare it with the model
the file compiles to now: a changed model (a trunk's mass edited, a shank replaced) is one line. A checkpoint
without the record (an earlier version's) or of a Gymnasium env without env.xml_file is not checked, nor is one
recorded under another MuJoCo version (its binary format may differ)."""

from __future__ import annotations

import hashlib
from typing import Optional

import numpy as np

from ppo_torchrl.errors import ConfigError


def model_record(env_cfg) -> Optional[dict]:
    """{"sha256", "mujoco", "file"} of the env's model file, or None for an env without env.xml_file."""
    xml_file = env_cfg.get("xml_file")
    if not xml_file:
        return None
    import mujoco

    from ppo_torchrl.envs.make import resolve_model_file

    path = resolve_model_file(str(xml_file))
    try:
        model = mujoco.MjModel.from_xml_path(str(path))
    except Exception:  # noqa: BLE001 - the env's own checks say what is wrong with a model that does not compile
        return None
    buffer = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
    mujoco.mj_saveModel(model, None, buffer)
    return {"sha256": hashlib.sha256(buffer.tobytes()).hexdigest(), "mujoco": mujoco.__version__, "file": str(path)}


def check_model(state: dict, env_cfg, what: str) -> None:
    """The checkpoint `state` was trained on the model env_cfg's xml_file compiles to now, or one ConfigError
    line that says what to run. `what`: the command's words (resume=<dir>, run=<dir>)."""
    recorded = state.get("model")
    if not isinstance(recorded, dict) or not isinstance(recorded.get("sha256"), str):
        return  # a run of an earlier version: it recorded no model
    now = model_record(env_cfg)
    if now is None or now["mujoco"] != recorded.get("mujoco") or now["sha256"] == recorded["sha256"]:
        return
    raise ConfigError(f"{what}: the robot model env.xml_file={env_cfg.xml_file} ({now['file']}) is not the one this "
                      "run trained on (its compiled model's sha256 differs from the one the checkpoint recorded: a "
                      "mass, size or joint changed); put the model back, give the one it trained on with "
                      "env.xml_file=<file>, or train anew on this one (hydra.run.dir=<dir>, or overwrite=true)")
