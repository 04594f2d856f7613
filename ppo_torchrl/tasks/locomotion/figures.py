"""What an evaluation of a locomotion task reports beyond returns and lengths (evaluate.py's record of a MuJoCo base
or a legged task): forward velocity along the heading, the step's crossings (success: beyond the line and not
terminated), the gait figures per foot and per pair of feet, the drives against their limits; the lines evaluate
prints of them, and the metrics columns and summary keys a training run logs of them (`figures` returns which).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from ppo_torchrl.robots.gait import FOOT_PAIRS

# What an eval of a locomotion env adds: gait_figures' keys and the feet's names (also in summary.json and the
# height sweep). Per foot, in the model's foot order (`feet`): foot_contact_share, the share of time on the ground,
# touchdown_frequency (Hz) and longest_air_s, the longest time it was off the ground in any episode (a foot
# held up for seconds shows here); longest_air_moving_s counts only the time the robot moved (not a standstill).
# <kind>_pairs_together: of the time a foot of a pair is down, the share both are, the two pairs of a kind pooled
# (locomotion.FOOT_PAIRS): diagonal LF+RH, RF+LH (a trot: near 1), same_side LF+LH, RF+RH (a pace), same_end
# LF+RF, LH+RH (a bound); only for four feet, one at each corner.
PAIR_KEYS = tuple(f"{kind}_pairs_together" for kind in FOOT_PAIRS)
# Per foot in each episode's outcome (eval.json) and row (height_sweep_episodes.csv): a worst case over the eval
# (longest_air_moving_s) shows whether one episode or every one holds a foot up.
EPISODE_FOOT_KEYS = ("foot_contact_share", "touchdown_frequency", "longest_air_moving_s")
# Per episode too, a robot read from its model (env=legged): the largest |joint torque| / the model's own limit and
# the share of time a joint was at its limit (robots/gait.py); over the eval, the max and the pooled share.
EPISODE_TORQUE_KEYS = ("peak_torque_share", "torque_at_limit_share")
GAIT_KEYS = ("stride_frequency", "duty_factor", "peak_joint_speed", "over_speed_limit_share", "body_contact_share",
             "feet", "foot_contact_share", "touchdown_frequency", "longest_air_s", "longest_air_moving_s", *PAIR_KEYS,
             *EPISODE_TORQUE_KEYS)


def gait_figures(gaits: list, speed_limit: Optional[float]) -> dict:
    """Per-episode gait figures (locomotion.GaitMeter) over the eval: means (each foot's too), the peak joint
    speed's max, the pairs' time down together over all the eval's time and, with a speed limit, the share of all
    the eval's physics steps in which a joint was over it."""
    figures = {key: float(np.mean([g[key] for g in gaits]))
               for key in ("stride_frequency", "duty_factor", "body_contact_share")}
    for key in ("foot_contact_share", "touchdown_frequency"):
        figures[key] = np.mean([g[key] for g in gaits], axis=0).tolist() if gaits[0][key] else []
    for key in ("longest_air_s", "longest_air_moving_s"):
        figures[key] = np.max([g[key] for g in gaits], axis=0).tolist() if gaits[0][key] else []
    for kind in gaits[0]["pair_together_time_s"]:
        down = sum(g["pair_down_time_s"][kind] for g in gaits)
        together = sum(g["pair_together_time_s"][kind] for g in gaits)
        figures[f"{kind}_pairs_together"] = float(together / down) if down > 0 else None
    figures["peak_joint_speed"] = float(max(g["peak_joint_speed"] for g in gaits))
    figures["peak_torque_share"] = figures["torque_at_limit_share"] = None  # None: the model's limits not known
    if gaits[0]["peak_torque_share"] is not None:
        figures["peak_torque_share"] = float(max(g["peak_torque_share"] for g in gaits))
        at_limit = sum(g["torque_at_limit_share"] * g["time_s"] for g in gaits)
        figures["torque_at_limit_share"] = float(at_limit / max(sum(g["time_s"] for g in gaits), 1e-9))
    if speed_limit is not None:
        figures["joint_speed_limit"] = float(speed_limit)
        over = sum(g["over_speed_limit_time_s"] for g in gaits)
        figures["over_speed_limit_share"] = float(over / max(sum(g["time_s"] for g in gaits), 1e-9))
    return figures


def figures(cfg, episodes: dict, result: dict) -> None:
    """Adds the locomotion figures of `episodes` (evaluate.run_episodes' record) to `result` (evaluate.summarize's),
    each episode's to its outcome, and says what a training run logs: result["columns"] (metrics.csv's eval
    columns) and result["task_keys"] (the figures summary.json keeps)."""
    returns, lengths, distances = episodes["returns"], episodes["lengths"], episodes["distances"]
    crossed, gaits, terminated = episodes["crossed"], episodes["gaits"], episodes["terminated"]
    beyond = None  # per episode: beyond the success line when the episode ended
    if distances:
        # Forward progress of the base along its heading: mean velocity over each episode, and where it ended.
        dt = episodes["dt"]
        velocities = [d / (n * dt) for (d, _), n in zip(distances, lengths)]
        result.update(forward_velocity_mean=float(np.mean(velocities)), forward_velocity_std=float(np.std(velocities)),
                      x_final_mean=float(np.mean([x1 for _, x1 in distances])))
        if crossed:  # a step env: the env's line, the trunk success_margin beyond the step's edge
            beyond = crossed
            result.update(success_margin=episodes["success_margin"],
                          step_height_mean=float(np.mean(episodes["heights"])))
        elif cfg.eval.get("success_x") is not None:
            beyond = [x1 >= cfg.eval.success_x for _, x1 in distances]
            result["success_x"] = float(cfg.eval.success_x)
    if beyond is not None:
        # success: beyond the line when the episode ends, and the episode did not end by a fall or a forbidden
        # contact (terminated); crossed_at_end_rate counts the line alone, terminated episodes too
        result.update(success_rate=float(np.mean([b and not t for b, t in zip(beyond, terminated)])),
                      crossed_at_end_rate=float(np.mean(beyond)))
    if gaits:
        result["feet"] = list(episodes["feet"])
        result.update(gait_figures(gaits, cfg.env.locomotion.get("joint_speed_limit")))
    for i, outcome in enumerate(result["outcomes"]):
        if beyond is not None:
            outcome.update(crossed=bool(beyond[i]), success=bool(beyond[i] and not outcome["terminated"]))
        if gaits:
            outcome.update({key: gaits[i][key] for key in (*EPISODE_FOOT_KEYS, *EPISODE_TORQUE_KEYS)})
    result["task_keys"] = [k for k in ("forward_velocity_mean", "success_rate", *GAIT_KEYS) if k in result]
    result["columns"] = {column: result[key] for column, key in COLUMNS.items() if result.get(key) is not None}


# metrics.csv's eval columns of the task (LeggedTask.metric_keys) a training run fills from these figures
COLUMNS = {"eval/forward_velocity": "forward_velocity_mean", "eval/success_rate": "success_rate"}


def ended_line(result: dict) -> str:
    """'8% end terminated (5% contact: trunk, 3% fall)'; an env that gives no reason: '8% end terminated'."""
    reasons = ", ".join(f"{share:.0%} {why}" for why, share in result["termination_shares"].items()
                        if why != "terminated")
    return f"{result['terminated_share']:.0%} end terminated" + (f" ({reasons})" if reasons else "")


def motion_line(result: dict) -> str:
    """The eval's figures after return and length, one topic a line (each starting '\n  '): where the robot went
    (forward velocity where the env moves, the step's crossings, terminations), its gait, each foot, the pairs."""
    lines = []
    moving = "forward_velocity_mean" in result and (result["forward_velocity_mean"] or result["forward_velocity_std"]
                                                    or "success_rate" in result)
    honest = (f"and are not terminated ({result['crossed_at_end_rate']:.0%} are beyond it at the end; "
              f"{ended_line(result)})") if "success_rate" in result else ""
    went = [f"forward velocity {result['forward_velocity_mean']:.2f} +- {result['forward_velocity_std']:.2f} m/s"] \
        if moving else []
    if "success_margin" in result:
        went.append(f"{result['success_rate']:.0%} of episodes cross the line {result['success_margin']:.3g} m beyond the "
                    f"step ({result['step_height_mean'] * 100:.0f} cm on average) {honest}")
    elif "success_rate" in result:
        went.append(f"{result['success_rate']:.0%} of episodes end beyond x={result['success_x']} m {honest}")
    elif result.get("terminated_share"):
        went.append(ended_line(result))
    if went:
        lines.append(", ".join(went))
    if "stride_frequency" in result:
        limit = (f" (limit {result['joint_speed_limit']:g}, passed {result['over_speed_limit_share']:.2%} of the time)"
                 if "joint_speed_limit" in result else "")
        lines.append(f"gait: stride frequency {result['stride_frequency']:.1f} Hz, duty factor "
                     f"{result['duty_factor']:.2f}, peak joint speed {result['peak_joint_speed']:.1f} rad/s{limit}, "
                     f"a non-foot body on the ground {result['body_contact_share']:.0%} of the time"
                     + (f", joint torque up to {result['peak_torque_share']:.0%} of the model's limit (at it "
                        f"{result['torque_at_limit_share']:.1%} of the time)" if result.get("peak_torque_share") is not None else ""))
        if result["feet"]:
            feet = zip(result["feet"], result["foot_contact_share"], result["touchdown_frequency"],
                       result["longest_air_s"], result["longest_air_moving_s"])
            lines.append("per foot (share of time on the ground, touchdowns/s, longest time in the air in s (of it "
                         "while moving)): " + ", ".join(f"{name} {share:.2f} {rate:.1f} {air:.2f} ({moving_s:.2f})"
                                                        for name, share, rate, air, moving_s in feet))
        pairs = [(key[:-len("_pairs_together")].replace("_", " "), result[key]) for key in PAIR_KEYS
                 if result.get(key) is not None]
        if pairs:
            lines.append("feet of a pair down together, of the time one is: " +
                         ", ".join(f"{kind} {share:.2f}" for kind, share in pairs))
    return "".join(f"\n  {line}" for line in lines)
