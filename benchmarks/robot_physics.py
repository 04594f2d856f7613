"""Frames/s of env=legged's env step per robot, the physics as it was (A: env.legged.contacts=model, the model's
own timestep) against as it is (B: the config's defaults), interleaved A/B in one process (issue 59, item 4).

    .venv/bin/python benchmarks/robot_physics.py [--steps 1000] [--repeats 5] [--robots go1,anymal_b]
        [--out results/speed/robots_physics_<date>.md] [--a override ...] [--b override ...]

Each robot is built twice (experiment=legged_trot, the curriculum off: a flat start), A then B; each repeat steps
A and B for --steps control steps (a frame is one control step) with the same random actions (N(0, 0.4^2)
clipped to [-1, 1], the recipe's initial policy std; seed 0), resetting on each end, in the order AB, BA, AB, ...
so that a load that drifts through the run falls on both. The table gives each side's median over the repeats
and its spread (min-max), the ratio of the medians, and the contacts per physics step (all, and robot-robot)
seen on each side. --a / --b add overrides to one side (e.g. --b env.legged.physics_dt=0.004 to try a step).
--where also prints, per side, where the env step goes: mj_step's time and share, mj_collision's share of it, and
the geom pairs the collision filters let through (robot-robot, robot-terrain).
Other processes on the machine move the figures: the file notes the load average before and after.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import math
import os
import platform
import statistics
import sys
import time
import warnings
from pathlib import Path

import mujoco
import numpy as np

warnings.filterwarnings("ignore")
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT)]  # this checkout's package

from ppo_torchrl.compose import compose  # noqa: E402
from ppo_torchrl.envs import make_gym_env  # noqa: E402

MENAGERIE = ROOT / "ppo_torchrl" / "assets" / "menagerie"
BEFORE = ["env.legged.contacts=model", "env.legged.physics_dt=model"]


def build(scene: Path, overrides: list):
    cfg = compose(["experiment=legged_trot", f"env.xml_file={scene}", "env.terrain.curriculum=false", *overrides])
    env = make_gym_env(cfg.env)
    label = f"contacts={cfg.env.legged.contacts}, physics_dt={cfg.env.legged.physics_dt}"
    return env, math.exp(cfg.policy.log_std_init) + cfg.policy.std_min, label


def rate(env, actions) -> tuple:
    """(control steps per second, contacts per physics-step sample, robot-robot contacts per sample)."""
    u = env.unwrapped
    env.reset(seed=0)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    steps_per_s = len(actions) / (time.perf_counter() - start)
    model, data = u.model, u.data
    env.reset(seed=0)
    contacts = robot_robot = 0
    for action in actions[: len(actions) // 4]:  # not timed: the contacts the step leaves
        _, _, terminated, truncated, _ = env.step(action)
        geoms = data.contact.geom[: data.ncon]
        contacts += data.ncon
        if len(geoms):
            robot_robot += int(np.count_nonzero(model.body_weldid[model.geom_bodyid[geoms]].min(axis=1) > 0))
        if terminated or truncated:
            env.reset()
    samples = max(1, len(actions) // 4)
    return steps_per_s, contacts / samples, robot_robot / samples


def candidate_pairs(model) -> tuple:
    """(robot-robot, robot-terrain) geom pairs that pass MuJoCo's filters (contype/conaffinity, same or welded body,
    parent-child, excludes): what the broadphase has to cull or the narrow phase to test."""
    excluded = {(int(b) >> 16, int(b) & 0xFFFF) for b in model.exclude_signature}
    parent = not model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_FILTERPARENT
    weld, counts = model.body_weldid, [0, 0]
    for g1, g2 in itertools.combinations(range(model.ngeom), 2):
        w1, w2 = weld[model.geom_bodyid[g1]], weld[model.geom_bodyid[g2]]
        if w1 == w2 or not (model.geom_contype[g1] & model.geom_conaffinity[g2]
                            or model.geom_contype[g2] & model.geom_conaffinity[g1]):
            continue
        if parent and w1 and w2 and (weld[model.body_parentid[w1]] == w2 or weld[model.body_parentid[w2]] == w1):
            continue
        if (min(w1, w2), max(w1, w2)) in excluded:
            continue
        counts[0 if w1 and w2 else 1] += 1
    return tuple(counts)


def where(env, actions) -> str:
    """Where one side's env step goes: mj_step's time per call and share of the env step (mj_step wrapped), and
    mj_collision's share of mj_step (re-run at the states the steps leave)."""
    u, real, spent = env.unwrapped, mujoco.mj_step, [0.0]

    def timed(model, data, nstep=1):
        start = time.perf_counter()
        real(model, data, nstep)
        spent[0] += time.perf_counter() - start

    env.reset(seed=0)
    mujoco.mj_step = timed  # gymnasium's MujocoEnv calls mujoco.mj_step(model, data, nstep=frame_skip)
    try:
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
        wall = time.perf_counter() - start
    finally:
        mujoco.mj_step = real
    per_step = spent[0] / (len(actions) * u.frame_skip)
    collision = 0.0
    for action in actions[: len(actions) // 4]:
        env.step(action)
        start = time.perf_counter()
        mujoco.mj_collision(u.model, u.data)
        collision += time.perf_counter() - start
    robot_robot, robot_terrain = candidate_pairs(u.model)
    return (f"{u.model.ngeom} geoms, candidate pairs robot-robot {robot_robot} / robot-terrain {robot_terrain}, "
            f"mj_step {per_step * 1e6:.1f} us ({spent[0] / wall:.0%} of the env step), mj_collision "
            f"{collision / max(1, len(actions) // 4) / per_step:.0%} of mj_step")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--robots", default=None, help="model names or folders, comma-separated (default: all)")
    parser.add_argument("--out", default=None, help="write the markdown table here")
    parser.add_argument("--a", nargs="*", default=[], help="more overrides for A (before)")
    parser.add_argument("--b", nargs="*", default=[], help="more overrides for B (after)")
    parser.add_argument("--where", action="store_true", help="also print where each side's env step goes")
    args = parser.parse_args()
    scenes = sorted(MENAGERIE.glob("*/scene.xml"))
    if args.robots:
        wanted = args.robots.split(",")
        scenes = [s for s in scenes if any(w == s.parent.name or s.parent.name.endswith("_" + w) for w in wanted)]
    load_before = os.getloadavg()
    rows = []
    for scene in scenes:
        env_a, std, label_a = build(scene, BEFORE + args.a)
        env_b, _, label_b = build(scene, args.b)
        name = env_b.unwrapped.robot.name
        actions = np.clip(std * np.random.default_rng(0).normal(size=(args.steps, env_a.action_space.shape[0])), -1, 1)
        figures = {"A": [], "B": []}
        contacts = {}
        for repeat in range(args.repeats):
            for side in ("AB" if repeat % 2 == 0 else "BA"):
                steps_per_s, all_c, self_c = rate(env_a if side == "A" else env_b, actions)
                figures[side].append(steps_per_s)
                contacts[side] = (all_c, self_c)
        ua, ub = env_a.unwrapped, env_b.unwrapped
        if args.where:
            print(f"{name} A: {where(env_a, actions)}\n{name} B: {where(env_b, actions)}", flush=True)
        a, b = statistics.median(figures["A"]), statistics.median(figures["B"])
        row = (f"| {name} | {ua.model.opt.timestep * 1e3:.3g} ms x{ua.frame_skip}, model | "
               f"{ub.model.opt.timestep * 1e3:.3g} ms x{ub.frame_skip}, {ub._legged.get('contacts')} | "
               f"{a:.0f} ({min(figures['A']):.0f}-{max(figures['A']):.0f}) | "
               f"{b:.0f} ({min(figures['B']):.0f}-{max(figures['B']):.0f}) | {b / a:.2f} | "
               f"{contacts['A'][0]:.2f} / {contacts['A'][1]:.2f} | {contacts['B'][0]:.2f} / {contacts['B'][1]:.2f} |")
        print(row, flush=True)
        rows.append(row)
        env_a.close()
        env_b.close()
    load_after = os.getloadavg()
    command = "python benchmarks/robot_physics.py " + " ".join(sys.argv[1:])
    now = datetime.datetime.now(datetime.timezone.utc)
    text = "\n".join([
        f"# env=legged physics: frames/s before (A) and after (B), {now:%Y-%m-%d %H:%M} UTC",
        "",
        f"`{command}`",
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}; "
        f"load average (1, 5, 15 min) {load_before[0]:.2f}, {load_before[1]:.2f}, {load_before[2]:.2f} before and "
        f"{load_after[0]:.2f}, {load_after[1]:.2f}, {load_after[2]:.2f} after. One env, {args.steps} control steps "
        f"(frames) of random actions per repeat, {args.repeats} repeats interleaved A/B; median (min-max) frames/s.",
        f"A: {label_a} ({' '.join(BEFORE + args.a)}). B: {label_b} ({' '.join(args.b) or 'the defaults'}).",
        "Contacts: per physics step after a control step, all / robot-robot (a quarter of the steps sampled).",
        "",
        "| robot | A physics | B physics | A frames/s | B frames/s | B / A | A contacts | B contacts |",
        "|---|---|---|---|---|---|---|---|",
        *rows, ""])
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
