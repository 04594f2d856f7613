"""env=quadruped_a1like before training: heading=auto, the feet found, 5 s under zero action from reset
(seed 0), and the forward velocity when pushed along the nose with heading=auto and with heading=x.
Run from the repo root:
    python benchmarks/a1like_stand_check.py
"""
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

import ppo_torchrl.config  # noqa: F401  (registers the schemas)
from ppo_torchrl.envs import make_gym_env

CONF = str(Path(__file__).resolve().parents[1] / "conf")


def env_of(*overrides):
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return make_gym_env(compose(config_name="config", overrides=["env=quadruped_a1like", *overrides]).env)


env = env_of()
loco = env.unwrapped
print(f"heading (auto): {loco.heading.tolist()}; feet: {[loco.model.geom(int(g)).name for g in loco.feet]}; "
      f"mass {loco.model.body_subtreemass[loco.model.body('trunk').id]:.2f} kg; trunk z in the model {loco._init_z:.3f} m")
env.reset(seed=0)
heights = []
for step in range(250):  # 5 s at 50 Hz
    _, reward, terminated, _, _ = env.step(np.zeros(12, np.float32))
    heights.append(float(loco.data.qpos[2]))
    if terminated:
        break
feet, others = loco._contacts()
print(f"zero action: {step + 1} steps ({(step + 1) * loco.dt:.1f} s), terminated {terminated}; trunk z min "
      f"{min(heights):.3f}, final {heights[-1]:.3f} m; feet down {feet.tolist()}; non-foot geoms on the ground {others}; "
      f"drift {np.linalg.norm(loco.data.qpos[:2]):.3f} m")
for heading in ("auto", "x"):
    pushed = env_of(f"env.locomotion.heading={heading}")
    pushed.reset(seed=0)
    pushed.unwrapped.data.qvel[0] = -1.0  # 1 m/s along the nose: world -x
    info = pushed.step(np.zeros(12, np.float32))[4]
    print(f"pushed 1 m/s along the nose, heading={heading}: forward_velocity {info['forward_velocity']:.3f} m/s")
