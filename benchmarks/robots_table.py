"""The real robots' table (issue 46): one row per robot read from its model, from each robot's height sweep
(`python -m ppo_torchrl.evaluate run=<robot dir> checkpoint=last episodes=100 seed=<s> heights=0,0.2l,0.25l,0.3l
out=<robot dir>/<sweep>`), and each goal of issue 46 item 5 met or missed, robot by robot.

    python benchmarks/robots_table.py <robot dir>[:<sweep dir>] [...] [--sweep sweep] [--goal go1=0.9 ...] [--out table.md]
    python benchmarks/robots_table.py results/robots/legged_v2_2026-11-28/*_seed1[23] --goals 59 --out <table.md>

<sweep dir> defaults to <robot dir>/<--sweep>. The robot (name, mass, leg length l, feet by corner) is read
again from the model file the run trained on (its .hydra/config.yaml), so the figures are per corner: LF RF LH
RH. Success is issue 31's (crossed and not terminated). Goals: a step of 0.25 l crossed by >= the robot's
--goal (default 0.8; 0.9 for the tuning robots Go1 and ANYmal B); flat ground >= 95% at >= 0.25 sqrt(g l);
each foot on the ground 35-65% of the time, no foot up > 0.5 s while moving, strides under 3 Hz (flat and
0.25 l); the joint torques: the largest share of the model's limit and the time some joint is at it.
--goals 59 (issue 59's, one row per run dir, named by it): 0.25 l >= 90% on every robot; a foot up > 0.5 s while
moving in <= 10% of episodes; drives at their torque limit <= 25% of the time; and, where the run dir has them, the
success at 0.25 l with the grip halved (sweep_grip_half/) and the trunk 10% heavier (sweep_trunk_heavier/), no goal.
--goals 59 adds a third table (and a fourth, one row per robot with its runs side by side, a README's): the 0.25 l episodes that did not succeed, by how they ended (a geom on the ground or
the step, a fall, short of the line at the time limit, or across and then ended), and the curriculum's top step
(metrics.csv's env/terrain_level): the frame it first reached 0.25 l and where it was at the end, in l. What a
missed 0.25 l goal is made of.
--curves <png>: each run's training curves (metrics.csv or its .xz): the train return, the in-training eval's success
at 0.25 l, the curriculum's step and the policy's std.
Bad input (a missing dir, a run that is not env=legged, a sweep dir without a height sweep, a malformed --goal, a
directory as --out or --curves) is one `error:` line and exit 2, before anything is written (cli_args.py).
"""

import math
import sys
from collections import Counter
from pathlib import Path

from cli_args import ConfigError, Parser, goal, out_file
from cli_args import run as run_main
from robot_row import CURVES, SHARE, STRIDE_HZ, SWING_S, curves, load, long_swings

from ppo_torchrl.envs.make import resolve_model_file
from ppo_torchrl.records import has_record
from ppo_torchrl.report import read_metrics
from ppo_torchrl.robots.model import GRAVITY, read_robot

FLAT_GOAL, SPEED_GOAL, STEP = 0.95, 0.25, 0.25  # flat success, flat speed in sqrt(g l), the step in l
TUNING_GOAL = {"go1": 0.9, "anymal_b": 0.9}
ISSUE59 = {"step": 0.9, "long_swing_episodes": 0.10, "torque_at_limit": 0.25}
WORLDS = (("grip halved", "sweep_grip_half"), ("trunk +10%", "sweep_trunk_heavier"))
PANELS = (CURVES[0], CURVES[2], CURVES[3], ("policy/scale_mean", "the policy's std (mean over joints)"))  # --curves


def robot_of(run_dir: Path):
    """The robot a run trained on, read again from its model; one line for a dir that is not a legged run."""
    from ppo_torchrl.config_data import read_config

    saved = run_dir / ".hydra" / "config.yaml"  # a tuning record keeps the run's config.yaml only
    saved = saved if saved.is_file() else run_dir / "config.yaml"
    if not run_dir.is_dir():
        raise ConfigError(f"{run_dir}: no such run dir")
    if not saved.is_file():
        raise ConfigError(f"{run_dir} is not a ppo_torchrl run dir (no config.yaml)")
    env = read_config(saved).env  # data only: nothing in it is resolved (config_data.py)
    if env.get("legged") is None or not env.get("xml_file"):
        raise ConfigError(f"{run_dir} is a run of {env.get('id')}, not of env=legged: the table's rows are robots read "
                          "from their model (make robot)")
    return read_robot(resolve_model_file(env.xml_file), env.legged.keyframe)


def sweep_of(path: Path) -> Path:
    """A sweep dir that holds evaluate heights='s files, or one line."""
    if not has_record(path / "height_sweep.json") or not has_record(path / "height_sweep_episodes.csv"):
        raise ConfigError(f"{path} holds no height sweep (height_sweep.json and height_sweep_episodes.csv, written by "
                          "python -m ppo_torchrl.evaluate ... heights=... out=<it>)")
    return path


def in_legs(sweep: dict, l: float) -> dict:
    """{height in l (3 decimals): that height's result}."""
    return {round(h / l, 3): r for h, r in sweep.items()}


def by_corner(robot, values) -> str:
    order = sorted(range(4), key=lambda i: ("LF", "RF", "LH", "RH").index(robot.corners[i]))
    return " ".join(f"{values[i]:.2f}" for i in order)


def misses(step: dict) -> str:
    """The 0.25 l episodes that did not succeed, by how they ended (issue 31's success: crossed, not terminated)."""
    ends = Counter(("across, then " + (o["termination"] or "ended")) if o["crossed"]
                   else o["termination"] or "short at the time limit" for o in step["outcomes"] if not o["success"])
    return ", ".join(f"{end} {n}" for end, n in ends.most_common()) or "none"


def curriculum(run_dir: Path, l: float) -> str:
    """When the curriculum's top step first reached 0.25 l, and where it was at the end of training, in l
    (metrics.csv's env/terrain_level)."""
    path = run_dir / "metrics.csv"
    m = read_metrics(path) if has_record(path) else {}
    seen = [(f, x) for f, x in zip(m.get("frames", []), m.get("env/terrain_level", [])) if not math.isnan(x)]
    if not seen:
        return "- | -"
    first = next((f for f, x in seen if x / l >= STEP - 1e-9), None)
    return f"{'never' if first is None else f'{first / 1e6:.1f}M'} | {seen[-1][1] / l:.2f} l"


def rows(entries: list, goals: dict, issue: int = 46) -> str:
    head = ("| robot | mass | l | 0.25 l | success per height (100 episodes each unless said) | flat speed "
            "| each foot on the ground LF RF LH RH: flat; 0.25 l | episodes with a foot up > 0.5 s moving: flat; 0.25 l "
            "| most touchdowns/s | joint torque: peak share of the limit, time at it |")
    out = [head, "|---|---|---|---|---|---|---|---|---|---|"]
    if issue == 59:
        out = [head + " 0.25 l: grip halved; trunk +10% |", out[1] + "---|"]
    verdicts, compact = [], []
    ends = ["", "| run | 0.25 l: the episodes that did not succeed, by how they ended "
            "| the curriculum's top step: first at 0.25 l (frames) | at the end |", "|---|---|---|---|"]
    for name, robot, sweep, worlds, run_dir in entries:
        l = robot.leg_length
        heights = in_legs(sweep, l)
        flat, step = heights.get(0.0), heights.get(STEP)
        n = sorted({len(r["outcomes"]) for r in heights.values()})
        success = ", ".join(f"{h:g} l {r['success_rate']:.0%}" for h, r in sorted(heights.items()))
        if n != [100]:
            success += f" ({'/'.join(map(str, n))} episodes)"
        scale = math.sqrt(GRAVITY * l)
        speed = (f"{flat['forward_velocity_mean']:.2f} m/s ({flat['forward_velocity_mean'] / scale:.2f} sqrt(g l))"
                 if flat else "-")
        shown = [r for r in (flat, step) if r]
        shares = "; ".join(by_corner(robot, r["foot_contact_share"]) for r in shown)
        swings = "; ".join(f"{long_swings(r)[0]:.0%}" for r in shown)
        stride = max(max(r["touchdown_frequency"]) for r in shown)
        torque = ", ".join(f"{r['peak_torque_share']:.2f} / {r['torque_at_limit_share']:.0%}" for r in shown)
        robust = "; ".join(f"{in_legs(w, l)[STEP]['success_rate']:.0%}" if w and STEP in in_legs(w, l) else "-"
                           for w in worlds)
        out.append(f"| {name} | {robot.mass:.1f} kg | {l:.3f} m | {STEP * l * 100:.1f} cm | {success} | {speed} "
                   f"| {shares} | {swings} | {stride:.2f} | {torque} |" + (f" {robust} |" if issue == 59 else ""))
        goal = goals.get(robot.name, ISSUE59["step"] if issue == 59 else TUNING_GOAL.get(robot.name, 0.8))
        checks = [
            ("0.25 l >= the robot's goal", step is not None and step["success_rate"] >= goal,
             f"{step['success_rate']:.0%}; goal {goal:.0%}" if step else "not run"),
            (f"flat >= {FLAT_GOAL:.0%}", flat is not None and flat["success_rate"] >= FLAT_GOAL,
             f"{flat['success_rate']:.0%}" if flat else "not run"),
            (f"flat speed >= {SPEED_GOAL} sqrt(g l)", flat is not None and flat["forward_velocity_mean"] >= SPEED_GOAL * scale,
             f"{flat['forward_velocity_mean'] / scale:.2f}" if flat else "not run"),
            (f"each foot down {SHARE[0]:.0%}-{SHARE[1]:.0%}",
             all(SHARE[0] <= x <= SHARE[1] for r in shown for x in r["foot_contact_share"]),
             f"{min(min(r['foot_contact_share']) for r in shown):.2f}-{max(max(r['foot_contact_share']) for r in shown):.2f}"),
            (f"no foot up > {SWING_S} s moving", all(long_swings(r)[0] == 0 for r in shown),
             f"{max(long_swings(r)[0] for r in shown):.0%} of episodes have one"),
            (f"strides under {STRIDE_HZ:g} Hz", stride < STRIDE_HZ, f"{stride:.2f}"),
        ]
        if issue == 59:  # a long swing in at most 10% of episodes (not none), and the drives' time at their limit
            most, at_limit = max(long_swings(r)[0] for r in shown), max(r["torque_at_limit_share"] for r in shown)
            checks[4] = (f"a foot up > {SWING_S} s moving in <= {ISSUE59['long_swing_episodes']:.0%} of episodes",
                         most <= ISSUE59["long_swing_episodes"], f"{most:.0%}")
            checks.append((f"drives at their limit <= {ISSUE59['torque_at_limit']:.0%} of the time",
                           at_limit <= ISSUE59["torque_at_limit"], f"{at_limit:.0%}"))
        verdicts.append((name, checks))
        compact.append((robot, name, step, flat, robust, checks))
        if issue == 59 and step is not None:  # the third table reads each run's metrics: issue 59's only
            ends.append(f"| {name} | {misses(step)} | {curriculum(run_dir, l)} |")
    out += ["", "| goal | " + " | ".join(name for name, _ in verdicts) + " |", "|---|" + "---|" * len(verdicts)]
    for i, (goal, _, _) in enumerate(verdicts[0][1]):
        cells = [f"{'met' if checks[i][1] else 'missed'} ({checks[i][2]})" for _, checks in verdicts]
        out.append(f"| {goal} | " + " | ".join(cells) + " |")
    if issue == 59:
        out += ends + ["", by_robot(compact)]
    return "\n".join(out) + "\n"


def by_robot(compact: list) -> str:
    """--goals 59's last table: one row per robot, its runs side by side (a / b, in the order given), the figures a
    README shows: 0.25 l and flat success, each foot's share down on flat ground, the long swings and the drives' time
    at their limit at 0.25 l, the two robustness worlds and the goals met."""
    out = ["| robot (mass, l, step) | run | crosses 0.25 l | flat | each foot down, flat: LF RF LH RH "
           "| foot up > 0.5 s (0.25 l) | drives at limit (0.25 l) | 0.25 l grip halved; trunk +10% | goals met of 7 |",
           "|---|---|---|---|---|---|---|---|---|"]
    groups: dict = {}
    for robot, name, step, flat, robust, checks in compact:
        pct = lambda r: f"{r['success_rate']:.0%}" if r else "-"  # noqa: E731
        cells = (name.rpartition("_")[2], pct(step), pct(flat),
                 by_corner(robot, flat["foot_contact_share"]) if flat else "-",
                 f"{long_swings(step)[0]:.0%}" if step else "-",
                 f"{step['torque_at_limit_share']:.0%}" if step else "-", robust, str(sum(c[1] for c in checks)))
        groups.setdefault(robot.name, (robot, []))[1].append(cells)
    for robot, runs in groups.values():
        l = robot.leg_length
        out.append(f"| {robot.name} ({robot.mass:.1f} kg, {l:.3f} m, {STEP * l * 100:.1f} cm) | "
                   + " | ".join(" / ".join(column) for column in zip(*runs)) + " |")
    return "\n".join(out)


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="+", help="<robot dir>[:<sweep dir>]")
    parser.add_argument("--sweep", default="sweep", help="the sweep's folder in each robot dir")
    parser.add_argument("--goal", nargs="*", type=goal, default=[], help="<robot>=<share at 0.25 l>, e.g. go1=0.9")
    parser.add_argument("--goals", type=int, choices=(46, 59), default=46, help="whose goals: issue 46's or 59's")
    parser.add_argument("--out", type=out_file)
    parser.add_argument("--curves", type=out_file, help="write each run's training curves here (PNG, one line per run)")
    args = parser.parse_args(argv)
    goals = dict(args.goal)
    entries, left_out = [], []
    for given in args.robots:  # every input read (and refused in one line) before anything is written
        run, _, sweep = given.partition(":")
        run = Path(run)
        robot = robot_of(run)
        if not (Path(sweep) if sweep else run / args.sweep).is_dir():
            if sweep:
                raise ConfigError(f"{given}: the sweep dir {sweep} does not exist")
            left_out.append(run)
            continue
        worlds = [load(sweep_of(run / folder), ".") if (run / folder).is_dir() else None for _, folder in WORLDS]
        entries.append((run.name if args.goals == 59 else robot.name, robot,
                        load(sweep_of(Path(sweep) if sweep else run / args.sweep), "."), worlds, run))
    if args.curves:
        curves([Path(r.partition(":")[0]) for r in args.robots], args.curves, PANELS)
    if not entries:  # no table to make: the curves (read from the runs' metrics) were all that could be asked
        if args.curves:
            return 0
        raise ConfigError(f"none of the {len(args.robots)} run(s) given has its sweep ({args.sweep}/ or "
                          "<run>:<sweep dir>)")
    for run in left_out:
        print(f"{run}: no sweep yet, left out (make robot sweeps a run when it ends)", file=sys.stderr)
    text = rows(entries, goals, args.goals)
    if args.out:
        args.out.write_text(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
