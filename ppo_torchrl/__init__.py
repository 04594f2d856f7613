"""ppo_torchrl: PPO for MuJoCo robots, built from TorchRL components and wired by Hydra."""

import importlib.util
import os
import sys

# Headless rendering: EGL works on machines without a display (set MUJOCO_GL to override).
os.environ.setdefault("MUJOCO_GL", "egl")
# numpy's OpenBLAS on one thread (read when numpy loads it; set it to override), as torch runs on torch_threads (1):
# the fast collectors' numpy copy of the policy multiplies a few rows per env step, which OpenBLAS splits over threads
# from 512-wide layers on; on this busy 2-core machine an 8 x 48 by 48 x 512 product then took ~3 ms instead of
# ~0.02 ms (env=playground's recipe, 512-256-128 networks: 416 against 2,210 collected frames/s).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# tensordict asks importlib whether pandas is installed each time it builds a TensorDict from a dict,
# three times per loss call. Without pandas that is a search of sys.path every time (~13% of the
# update); a None entry in sys.modules is the standard "not installed" answer and costs nothing.
if "pandas" not in sys.modules and importlib.util.find_spec("pandas") is None:
    sys.modules["pandas"] = None

# `python -m ppo_torchrl[.evaluate|.export|.report]` imports this package first, while argv[0] is
# still "-m": a Ctrl-C during the heavy imports that follow is one line, not a traceback.
if sys.argv[:1] == ["-m"]:
    from ppo_torchrl.cli import check_interpreter
    from ppo_torchrl.errors import guarded
    from ppo_torchrl.run.signals import install_for_startup

    install_for_startup()
    guarded(check_interpreter)  # the system Python, not the project's: one line before the heavy imports fail
    from ppo_torchrl.usage import answer_help, show_starting

    answer_help(sys.orig_argv)  # evaluate --help, export --help: the page before torch is imported
    show_starting()  # on a terminal: a first line at once, replaced by the command's own

__version__ = "0.1.0"
__all__ = ["train", "load", "evaluate_run", "Run", "Policy"]


def __getattr__(name: str):
    """The Python API (api.py), imported on first use (PEP 562): `python -m ppo_torchrl ...` does not pay for it,
    and the package's root imports none of its modules (each module may import the package's others)."""
    if name in __all__:
        return getattr(importlib.import_module("ppo_torchrl.api"), name)
    raise AttributeError(f"module 'ppo_torchrl' has no attribute {name!r}")
