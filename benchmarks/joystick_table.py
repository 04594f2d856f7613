"""Issue 73's joystick tuning round as a markdown table: per setting (the recipe as it is, `base`, and each lever),
every row's (robot x tuning seed) decision figures from its tracking set (`evaluate tracking=true extremes=true
episodes=5 seed=1000`: `eval/tracking.json`), and the decision by the rule fixed before the runs
(results/robots/joystick_tuning_2026-12-03/PLAN.md): a lever is kept when the mean of its rows' overall v_xy error
falls by more than `base`'s standard error (std / sqrt(n)), no row's yaw error, falls or falls at the extremes are
worse than `base`'s worst, and no robot's mean v_xy error gets worse.

    python benchmarks/joystick_table.py base=<dir> <label>=<dir> ... [--out table.md]
    python benchmarks/joystick_table.py report=<dir> [--out table.md]   # a report: each goal, the rows meeting it

Each dir holds one row dir per robot and seed, named `<robot>_seed<s>` (its `summary.json`, `eval/tracking.json` or
`eval/tracking.json.xz`). A row without its tracking set is listed as waiting and takes no part in a decision; a lever
is decided only on the robots and seeds `base` has too.
"""

from __future__ import annotations

import json
import lzma
import math
import re
import sys
from pathlib import Path

from cli_args import ConfigError, Parser, out_file
from cli_args import run as run_main
from levers_table import mean_std

ROW = re.compile(r"^(?P<robot>.+)_seed(?P<seed>\d+)$")


def read_json(path: Path):
    """The JSON at path, or at path + .xz as records keep it; None when neither is there."""
    for candidate, opener in ((path, open), (path.with_name(path.name + ".xz"), lzma.open)):
        if candidate.is_file():
            with opener(candidate, "rt") as f:
                return json.load(f)
    return None


def tracking(row: Path):
    return read_json(row / "eval" / "tracking.json")


def figures(result: dict) -> dict:
    """A row's decision figures: the nominal world's overall errors and falls, the worst extreme's falls, the command
    worst tracked (by v_xy error) and the standing command's joint motion."""
    nominal = result["worlds"]["nominal"]
    extremes = [w["overall"]["falls"] for name, w in result["worlds"].items() if name != "nominal"]
    worst = max(nominal["commands"], key=lambda c: c["v_xy_error"])
    stand = [c["joint_motion_rms"] for c in nominal["commands"] if c.get("joint_motion_rms") is not None]
    return {"v_xy": nominal["overall"]["v_xy_error"], "yaw": nominal["overall"]["yaw_rate_error"],
            "falls": nominal["overall"]["falls"], "falls_extremes": max(extremes) if extremes else None,
            "worst": f"{worst['command']} {worst['v_xy_error']:.3f}", "stand": max(stand) if stand else None}


def rows(setting: Path) -> tuple:
    """({(robot, seed): (figures, summary)} of the rows with a tracking set, [names of the rows still waiting])."""
    done, waiting = {}, []
    for row in sorted(p for p in setting.iterdir() if p.is_dir() and ROW.match(p.name)):
        m = ROW.match(row.name)
        result = tracking(row)
        if result is None:
            waiting.append(f"{m['robot']} seed {int(m['seed'])}")
            continue
        summary = json.loads((row / "summary.json").read_text()) if (row / "summary.json").is_file() else {}
        done[(m["robot"], int(m["seed"]))] = (figures(result), summary)
    return done, waiting


def worse(value, limit) -> bool:
    return value is not None and limit is not None and value > limit + 1e-12


def decide(lever: dict, base: dict) -> str:
    keys = sorted(set(lever) & set(base))
    if len(keys) < 2:
        return f"undecided ({len(keys)} row{'s' * (len(keys) != 1)} shared with base)"
    mine = [lever[k][0] for k in keys]
    theirs = [base[k][0] for k in keys]
    m, _ = mean_std([f["v_xy"] for f in mine])
    bm, bs = mean_std([f["v_xy"] for f in theirs])
    margin = bs / math.sqrt(len(keys))
    reasons = []
    if not bm - m > margin:
        reasons.append(f"v_xy {m - bm:+.3f} against a margin of {margin:.3f}")
    for name in ("yaw", "falls", "falls_extremes"):
        limits = [f[name] for f in theirs if f[name] is not None]
        if limits and any(worse(f[name], max(limits)) for f in mine):
            reasons.append(f"a row's {name} beyond base's worst {max(limits):.3f}")
    for robot in sorted({k[0] for k in keys}):
        own = [lever[k][0]["v_xy"] for k in keys if k[0] == robot]
        ref = [base[k][0]["v_xy"] for k in keys if k[0] == robot]
        if mean_std(own)[0] > mean_std(ref)[0] + 1e-12:
            reasons.append(f"{robot}'s mean v_xy worse")
    if reasons:
        return "rejected (" + "; ".join(reasons) + ")"
    return f"kept (v_xy {m - bm:+.3f} against a margin of {margin:.3f}, on {len(keys)} rows)"


GOALS = (("v_xy", "v_xy <= 0.05", 0.05), ("yaw", "yaw <= 0.05", 0.05), ("falls", "falls <= 1%", 0.01),
         ("falls_extremes", "worst extreme <= 5%", 0.05), ("stand", "standing joints < 0.05 rad", 0.05))


def goals(done: dict) -> str:
    """A report's reading (no base given): for each of issue 73's goals, the rows that meet it, and which do not."""
    parts = []
    for key, text, limit in GOALS:
        met = [k for k, (f, _) in done.items() if f[key] is not None and
               (f[key] < limit if key == "stand" else f[key] <= limit + 1e-12)]
        missed = sorted(k for k in done if k not in met)
        named = "; missed by " + ", ".join(f"{r} seed {s}" for r, s in missed) if 0 < len(missed) <= 3 else ""
        parts.append(f"{text} in {len(met)} of {len(done)} rows{named}")
    return "goals: " + ", ".join(parts)


def clock(seconds) -> str:
    """A wall time as h:mm, or - when the summary has none."""
    if not isinstance(seconds, (int, float)):
        return "-"
    minutes = round(seconds / 60)
    return f"{minutes // 60}:{minutes % 60:02d}"


def fps(value) -> str:
    return f"{value:,.0f}" if isinstance(value, (int, float)) else "-"


def fmt(value, digits: int = 3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def table(entries: list) -> str:
    found = {label: rows(path) for label, path in entries}
    base = found.get("base", ({}, []))[0]
    lines = ["| setting | row | frames | v_xy error (sqrt(g l)) | yaw error (sqrt(g / l)) | falls | falls, worst extreme | "
             "worst command (v_xy) | standing joints (rad rms) | wall (h:mm) | frames/s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    verdicts = []
    for label, _ in entries:
        done, waiting = found[label]
        for (robot, seed), (f, summary) in sorted(done.items()):
            frames = f"{summary['frames']:,}" if "frames" in summary else "-"
            extreme = "-" if f["falls_extremes"] is None else f"{f['falls_extremes']:.0%}"
            lines.append(f"| {label} | {robot} seed {seed} | {frames} | {fmt(f['v_xy'])} | {fmt(f['yaw'])} | "
                         f"{f['falls']:.0%} | {extreme} | {f['worst']} | {fmt(f['stand'])} | "
                         f"{clock(summary.get('wall_s'))} | {fps(summary.get('sps'))} |")
        for name in waiting:
            lines.append(f"| {label} | {name} | waiting (no tracking set yet) | | | | | | | | |")
        values = [f["v_xy"] for f, _ in done.values()]
        robots = sorted({k[0] for k in done})
        per_robot = ", ".join(f"{r} {mean_std([done[k][0]['v_xy'] for k in done if k[0] == r])[0]:.3f}" for r in robots)
        mean, std = mean_std(values)
        decision = "baseline" if label == "base" else decide(done, base) if "base" in found else goals(done)
        spread = f"{fmt(mean)} +- {fmt(std)} over {len(values)} rows" if len(values) > 1 else (
            f"{fmt(mean)} (one row)" if values else "no row yet")
        verdicts.append(f"- **{label}**: v_xy {spread} ({per_robot}); {decision}")
    return "\n".join(lines + [""] + verdicts) + "\n"


def entry(text: str) -> tuple:
    if "=" not in text:
        raise ConfigError(f"{text!r}: give <label>=<dir of row dirs>")
    label, path = text.split("=", 1)
    if not label or not Path(path).is_dir():
        raise ConfigError(f"{path}: no such directory" if label else f"{text!r}: give <label>=<dir of row dirs>")
    return label, Path(path)


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("entries", nargs="+", type=entry)
    parser.add_argument("--out", type=out_file, default=None)
    args = parser.parse_args(argv)
    text = table(args.entries)
    print(text, end="")
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
