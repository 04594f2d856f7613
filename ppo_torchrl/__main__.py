"""`python -m ppo_torchrl env=Hopper-v4 [overrides]`: train PPO, or sweep with `-m`.

Returns the final deterministic eval return (falling back to the last-100 training return), the
value a Hydra sweeper such as Optuna maximizes.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ppo_torchrl import config as _config  # noqa: F401  (registers the schemas)
from ppo_torchrl.envs import check_env_id, env_files
from ppo_torchrl.errors import ConfigError, report_and_exit

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> float:
    from ppo_torchrl.trainer import train

    run_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        check_env_id(cfg.env.id)
        summary = train(cfg, run_dir)
    except ConfigError as error:
        report_and_exit(error)
    for key in ("eval_return_mean", "train_return_last100"):
        if summary.get(key) is not None:
            return float(summary[key])
    return float("-inf")


def check_env_override(argv: list[str]) -> None:
    """`env=<name>` must name a file in conf/env; say which exist and how to use any other id."""
    for arg in argv:
        if arg.startswith("env=") and "," not in arg:
            name = arg.split("=", 1)[1]
            available = env_files()
            if name not in available:
                shown = ", ".join(n for n in available if n != "gym")
                raise ConfigError(
                    f"env={name} has no config file. Available: {shown}. "
                    f"For any other registered Gymnasium id use: env=gym env.id={name}"
                )


if __name__ == "__main__":
    try:
        check_env_override(sys.argv[1:])
    except ConfigError as err:
        report_and_exit(err)
    main()
