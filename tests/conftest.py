"""Shared fixtures: configs composed with Hydra's compose API, the way the app composes them."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import ppo_torchrl.config  # noqa: F401  (registers the schemas)

ROOT = Path(__file__).resolve().parent.parent
CONF = str(ROOT / "conf")

# A tiny run: two batches of 256 frames, 2 epochs of 4 minibatches, no periodic eval.
TINY = [
    "collector.frames_per_batch=256",
    "collector.total_frames=512",
    "loss.epochs=2",
    "loss.minibatch_size=64",
    "eval.every_frames=0",
    "eval.final_episodes=1",
    "checkpoint.every_frames=256",
    "logger=none",
]


def compose_config(overrides=(), return_hydra_config=False):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides), return_hydra_config=return_hydra_config)


@pytest.fixture
def tiny_cfg():
    def make(*overrides):
        return compose_config(["env=InvertedPendulum-v4", *TINY, *overrides])

    return make


def run_cli(*args, module="ppo_torchrl", timeout=300, cwd=None):
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    env.pop("PPO_TORCHRL_DEBUG", None)
    return subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd or ROOT, env=env)


def ran(main, args, capsys):
    """An entry point's main in-process through the one error path: (exit code, stderr lines); 0 when it returned."""
    from ppo_torchrl.errors import guarded

    try:
        guarded(main, args)
        code = 0
    except SystemExit as exit_:
        code = exit_.code
    return code, [line for line in capsys.readouterr().err.splitlines() if line.strip()]
