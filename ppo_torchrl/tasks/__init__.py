"""Tasks: what a batch of simulated robots is asked to do, composed of parts with one job each.

`tasks/locomotion/` is the legged robot's wing (env=legged): a robot read from its model (robots/model.py, the
recipe in robots/recipe.py), a terrain, a command, the contact sensors, one episode memory, and named reward
terms, stepped as one batched env (`LeggedBatchEnv`, N robots of one model, physics in C++ outside the GIL).
"""

FIGURES = {"locomotion": "ppo_torchrl.tasks.locomotion.figures",
           "playground": "ppo_torchrl.tasks.playground_figures"}  # an evaluation record's kind -> its figures


def figures_module(kind):
    """The module that summarizes and prints an evaluation record of `kind` (record["figures"]), or None."""
    import importlib

    return importlib.import_module(FIGURES[kind]) if kind in FIGURES else None


def figures_kind(env_cfg, mujoco: bool):
    """The kind of an evaluation record on the Gym path: a MuJoCo body's ('locomotion': its forward velocity), a
    Playground task's ('playground': its reward terms), or None (returns and lengths only)."""
    return "locomotion" if mujoco else "playground" if env_cfg.get("playground") is not None else None
