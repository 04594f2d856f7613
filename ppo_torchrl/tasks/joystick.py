"""A run's joystick, as evaluate's tracking=true and drive= find it: which of the app's tasks with a velocity command
the run trains, checked before any env is built, and the tracking set run in each world that task has.

Two tasks have one: env=legged with `command.kind=velocity` (experiment=legged_joystick, tasks/locomotion/: the
tracking set in its nominal world and, with extremes=true, at each corner of its randomization; drive=), and a
MuJoCo Playground joystick task (env=playground, tasks/playground_tracking.py: the nominal world only, no drive=).
evaluate.py asks here and names neither.
"""

from __future__ import annotations

from typing import Optional

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.tasks.locomotion.drive import drive, parse as parse_drive  # noqa: F401  drive=: env=legged's
from ppo_torchrl.tasks.locomotion.tracking import plot, table  # noqa: F401  one table and plot for every task's set


def kind(env_cfg) -> Optional[str]:
    """'legged' (a velocity-command env=legged run), 'playground' (env=playground) or None (no joystick)."""
    if env_cfg.get("playground") is not None:
        return "playground"
    from ppo_torchrl.envs.make import batched

    command = (env_cfg.get("legged") or {}).get("command") or {}
    return "legged" if batched(env_cfg) and command.get("kind") == "velocity" else None


def check(env_cfg, tracking: bool, driving: bool, extremes: bool, run_dir) -> None:
    """One ConfigError line where the run's task cannot give what tracking=, drive= or extremes= ask."""
    found = kind(env_cfg)
    if tracking and found == "playground":
        from ppo_torchrl.tasks.playground_tracking import layout_of

        layout_of(env_cfg)  # a task whose command and velocities it can find, or one line
        if extremes:
            raise ConfigError("extremes=true fixes the corners of env=legged's randomization; EnvPool's Playground "
                              "tasks randomize nothing the app can fix: leave it out")
    if (tracking and found is None) or (driving and found != "legged"):
        raise ConfigError(f"{'tracking=true' if tracking else 'drive='} measures a joystick run "
                          f"(experiment=legged_joystick: env.legged.command.kind=velocity; tracking=true also a "
                          f"Playground joystick task, env=playground); {run_dir} is not one")


def worlds(env_cfg, extremes: bool) -> list:
    """[(name, draw)]: the nominal world (draw None), then with extremes=true each corner of the randomization."""
    out = [("nominal", None)]
    if extremes:
        from ppo_torchrl.envs.make import gym_make_kwargs
        from ppo_torchrl.tasks.locomotion.tracking import extremes as corners

        out += corners(gym_make_kwargs(env_cfg)["legged"]["randomize"])
    return out


def track(cfg, ac, obs_stats, episodes: int, seed: int, draw=None) -> dict:
    """The tracking set's figures in one world (tasks/locomotion/tracking.py's result, whichever task)."""
    if kind(cfg.env) == "playground":
        from ppo_torchrl.tasks import playground_tracking

        return playground_tracking.track(cfg, ac, obs_stats, episodes, seed)
    from ppo_torchrl.envs.make import make_batch
    from ppo_torchrl.tasks.locomotion import tracking

    return tracking.track(make_batch, cfg, ac, obs_stats, episodes, seed, draw)
