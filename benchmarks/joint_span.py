"""How far the joints of env=quadruped and env=quadruped_a1like move: each model's compiled joint range
(first leg), the largest |joint angle| of the first leg in a 200-step random-action rollout (seed 0),
and the trunk's height after 5 s with the actuators off. Run from the repo root:
    python benchmarks/joint_span.py
"""
from pathlib import Path

import mujoco
import numpy as np
from hydra import compose, initialize_config_dir

import ppo_torchrl.config  # noqa: F401  (registers the schemas)
from ppo_torchrl.envs.make import ASSETS_DIR, make_batch

CONF = str(Path(__file__).resolve().parents[1] / "conf")

for name, xml in (("quadruped", "quadruped.xml"), ("quadruped_a1like", "quadruped_a1like.xml")):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        batch = make_batch(compose(config_name="config", overrides=[f"env={name}"]).env)  # one row
    loco = batch.world
    batch.reset(seed=0)
    rng, top = np.random.default_rng(0), np.zeros(12)
    for _ in range(200):
        _, _, terminated, _, _ = batch.step(rng.uniform(-1, 1, (1, 12)).astype(np.float32))
        top = np.maximum(top, np.abs(batch.datas[0].qpos[7:]))
        if terminated[0]:
            batch.reset()
    model = mujoco.MjModel.from_xml_path(str(ASSETS_DIR / xml))
    model.actuator_gainprm[:, 0] = 0  # actuators off
    model.actuator_biasprm[:, 1:3] = 0
    data = mujoco.MjData(model)
    for _ in range(1000):  # 5 s
        mujoco.mj_step(model, data)
    print(f"env={name}: joint ranges {loco.model.jnt_range[1:4].round(4).tolist()} rad; ctrlrange +- "
          f"{loco.model.actuator_ctrlrange[:3, 1].round(2).tolist()} rad; random rollout, max |q| "
          f"{top[:3].round(3).tolist()} rad; actuators off, trunk z after 5 s {data.qpos[2]:.3f} m")
