"""What env=legged reads from each robot's model and what the recipe asks of it (the start line's second
line), for any model files:

    python benchmarks/robot_facts.py ppo_torchrl/assets/menagerie/*/scene.xml > results/robots/legged_read_<date>/robots.txt
"""

import sys

from omegaconf import OmegaConf

from ppo_torchrl.config import LeggedConfig
from ppo_torchrl.robots.model import read_robot
from ppo_torchrl.robots.recipe import describe

if __name__ == "__main__":
    legged = OmegaConf.structured(LeggedConfig)
    for path in sys.argv[1:]:
        print(f"{path}: {describe(read_robot(path), legged)}")
