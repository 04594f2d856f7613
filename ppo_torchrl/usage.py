"""What a command shows before its heavy imports (the package's __init__ calls these): the usage pages of evaluate
and export, plain text, so that `--help` answers at once (under a second; it took 6-10 s), and on a terminal a
status line that the command's first real line replaces. Each page: (usage, the arguments with their defaults,
their meanings, what the command does)."""

from __future__ import annotations

import sys


def _evaluate():
    usage = ("python -m ppo_torchrl.evaluate run=<run dir> [checkpoint=best|last|<file>] [episodes=10] [video=false] "
             "[video_episodes=0] [video_length=<s>] [seed=0] [heights=<m,m,...> [out=<dir>]] [tracking=false [extremes=false]] [drive=<segments>] "
             "[env.<key>=<value> ...]")
    help = {
        "run": "the run dir to evaluate (one with checkpoints/), or latest, or latest/<env>: the newest run under outputs/",
        "checkpoint": "best, last, or a checkpoint file",
        "episodes": "number of deterministic episodes (per height with heights=)",
        "video": "also film the first episode: <run dir>/eval/<checkpoint>.mp4, real-time speed, the camera following "
                 "the robot (MUJOCO_GL=egl)",
        "video_episodes": "the episodes to film, numbered from 0, e.g. 0 or 0,3: one after the other in one mp4 "
                          "(implies video=true)",
        "video_length": "at most this many seconds of video in all, which is simulated time as videos play in real "
                        "time; empty: whole episodes (implies video=true)",
        "seed": "episode i starts from seed * 1000 + i: the same seed replays the same episodes",
        "heights": "step heights in m, e.g. 0,0.05,0.1,0.15,0.2, or in leg lengths for env=legged, 0,0.2l,0.25l,0.3l: "
                   "evaluate at each; writes height_sweep.csv and the success-rate curve height_sweep.png (to film "
                   "one height: env.terrain.step_height=<m> video=true)",
        "out": "where the eval writes its files: eval.json, the video, a height sweep's (empty: <run dir>/eval; a "
               "shipped run under zoo/ or results/: outputs/<its path>/)",
        "tracking": "a joystick run (env.legged.command.kind=velocity, or a Playground Go1 joystick task): `episodes` "
                    "episodes per command of a fixed set, each held; writes tracking.json, tracking.md and tracking.png "
                    "(tasks/locomotion/tracking.py, tasks/playground_tracking.py)",
        "drive": "a joystick run: film a scripted command sequence, name:vx,vy,yaw:seconds;... in the robot's units, "
                 "the command drawn in each frame: drive.mp4 (tasks/locomotion/drive.py)",
        "extremes": "with tracking=true, the same once per corner of the run's randomization (grip, trunk mass, "
                    "strength at their ends)",
    }
    about = ("Runs the policy deterministically on a fresh env with the run's frozen normalization stats, prints\n"
             "mean +- std return and length (MJCF robots: forward velocity, gait figures; step envs: the share of\n"
             "episodes that cross) and writes <run dir>/eval/eval.json.\n"
             "env.<key>=<value> changes the run's env config for this evaluation, e.g. env.terrain.step_height=0.1\n"
             "(a step height in m) or env.xml_file=quadruped_step.xml (a flat-ground run on the step).")
    spec = {"run": None, "checkpoint": "best", "episodes": 10, "video": False, "video_episodes": "0",
            "video_length": "", "seed": 0, "heights": "", "out": "", "tracking": False, "extremes": False, "drive": ""}
    return usage, spec, help, about


def _export():
    usage = "python -m ppo_torchrl.export run=<run dir> [checkpoint=best|last|<file>] [out=<dir>|<file>.pt]"
    help = {"run": "the run dir whose policy is exported (or latest, latest/<env>); writes <run dir>/policy.pt (for a "
                   "shipped run under zoo/ or results/: outputs/<its path>/policy.pt)",
            "checkpoint": "best, last, or a checkpoint file",
            "out": "where policy.pt goes instead: a dir (its policy.pt) or a file <name>.pt (a legged run's "
                   "<name>.onnx, <name>.json and deploy_mujoco.py go beside it; outside a run dir a file there with "
                   "other bytes is left alone, one error line)"}
    about = ("Writes the policy as TorchScript: a raw observation in, the deterministic action within the bounds\n"
             "out, normalization baked in; it runs with torch alone: torch.jit.load('policy.pt')(obs).")
    spec = {"run": None, "checkpoint": "best", "out": ""}
    return usage, spec, help, about


EVALUATE, EXPORT = _evaluate(), _export()
PAGES = {"ppo_torchrl.evaluate": EVALUATE, "ppo_torchrl.export": EXPORT}


def answer_help(argv: list) -> None:
    """`python -m ppo_torchrl.evaluate --help` (or export, -h): the page, exit 0, before the module's heavy imports.
    argv: the interpreter's own command line (sys.orig_argv)."""
    if "-m" not in argv[:-1]:
        return
    at = argv.index("-m")
    page, args = PAGES.get(argv[at + 1]), argv[at + 2:]
    if page is None or not {"--help", "-h"} & set(args):
        return
    from ppo_torchrl.cli import print_help

    usage, spec, help, about = page
    sys.stdout.flush()
    print_help(usage, {k: (help.get(k, ""), default) for k, default in spec.items()}, about)


STATUS = "ppo_torchrl: starting (loading torch) ..."


class _Erasing:
    """A terminal stream whose first write first erases the status line, then hands every write to the stream."""

    def __init__(self, stream, streams: list):
        self._stream, self._streams, self._erased = stream, streams, False

    def write(self, text: str) -> int:
        if not self._erased:
            for other in self._streams:
                other._erased = True
            self._stream.write("\r\x1b[K")
        return self._stream.write(text)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


def show_starting() -> None:
    """`python -m ppo_torchrl...` on a terminal: a status line at once (the imports take 3-6 s before the first real
    line), erased by the first line the command writes, on either stream; nothing when stderr is not a terminal, so
    a refusal stays one line in a pipe or a log."""
    if not (sys.stderr.isatty() and sys.stdout.isatty()):
        return
    sys.stderr.write(STATUS + "\r")
    sys.stderr.flush()
    streams: list = []
    sys.stdout, sys.stderr = _Erasing(sys.stdout, streams), _Erasing(sys.stderr, streams)
    streams += [sys.stdout, sys.stderr]
