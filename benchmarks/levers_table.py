"""Issue 75's tuning round as a markdown table: per env, the env file as it is (the baseline) and each lever tried on
it, every tuning seed's last-100 training return at the end of the run (the reported rows' metric), their mean +-
sample std, the final deterministic eval beside it, the wall time, and the decision by the rule fixed before the runs
(results/quality_1m_round4_tuning_2026-12-02/PLAN.md): a lever is kept when its mean beats the baseline's by more than
the baseline's standard error (std / sqrt(n)) and its worst seed is not below the baseline's worst.

    python benchmarks/levers_table.py <env>:<label>=<sweep dir> ... [--out table.md]

Each sweep dir holds one run dir per seed (a `-m seed=6,7,8` sweep); the label `base` is the env's baseline. A run
not finished is left out and said; a lever without a baseline of its env is listed undecided.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Optional

from cli_args import ConfigError, Parser, out_file
from cli_args import run as run_main


def runs(sweep: Path) -> tuple:
    """(finished summaries by seed, names of the runs left out)."""
    done, left = {}, []
    for summary in sorted(sweep.glob("*/summary.json")):
        s = json.loads(summary.read_text())
        if s.get("status") == "finished":
            done[int(s["seed"])] = s
        else:
            left.append(f"{summary.parent.name} ({s.get('status')})")
    return done, left


def mean_std(values: list) -> tuple:
    n = len(values)
    mean = sum(values) / n if n else float("nan")
    std = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1)) if n > 1 else float("nan")
    return mean, std


def flat(config: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in config.items():
        if isinstance(value, dict):
            out.update(flat(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def first_config(sweep: Path) -> Optional[dict]:
    import yaml

    first = next(iter(sorted(sweep.glob("*/config.yaml"))), None)
    return None if first is None else flat(yaml.safe_load(first.read_text()))


def overrides(sweep: Path, base: Optional[Path] = None) -> str:
    """The sweep's overrides as Hydra recorded them (<run>/.hydra/overrides.yaml); for records without it, the keys
    whose values differ from the base's config (seed, logger and run paths aside)."""
    import yaml

    first = next(iter(sorted(sweep.glob("*/.hydra/overrides.yaml"))), None)
    if first is not None:
        return " ".join(o for o in yaml.safe_load(first.read_text()) if not o.startswith(("seed=", "env=", "hydra.")))
    mine, theirs = first_config(sweep), first_config(base) if base is not None and base != sweep else None
    if mine is None or theirs is None:
        return ""
    skip = ("seed", "logger", "run_dir", "resume", "init_from")
    return " ".join(f"{k}={v}" for k, v in mine.items()
                    if theirs.get(k) != v and not k.split(".")[0] in skip and not k.startswith(skip))


def decide(lever: list, base: list) -> str:
    if not lever or len(base) < 2:
        return "undecided (no baseline)" if len(base) < 2 else "no finished seed"
    m, _ = mean_std(lever)
    bm, bs = mean_std(base)
    margin = bs / math.sqrt(len(base))
    keep = m - bm > margin and min(lever) >= min(base)
    return (f"{'kept' if keep else 'rejected'} ({m - bm:+.0f} against a margin of {margin:.0f}; worst seed "
            f"{min(lever):.0f} vs {min(base):.0f})")


def table(entries: list) -> str:
    by_env: dict = {}
    for env, label, sweep in entries:
        by_env.setdefault(env, []).append((label, sweep))
    lines = []
    for env, items in by_env.items():
        found = {label: runs(sweep) for label, sweep in items}
        base = found.get("base", ({}, []))[0]
        base_sweep = dict(items).get("base")
        base_returns = [s["train_return_last100"] for s in base.values()]
        lines += [f"## {env}", "", "| setting | overrides | train return, last 100 (per seed) | mean +- std | "
                  "final eval mean | wall s (mean) | decision |", "|---|---|---|---|---|---|---|"]
        for label, sweep in items:
            done, left = found[label]
            returns = [done[k]["train_return_last100"] for k in sorted(done)]
            mean, std = mean_std(returns)
            evals = [done[k]["eval_return_mean"] for k in sorted(done)]
            walls = [done[k]["wall_s"] for k in sorted(done)]
            per_seed = ", ".join(f"{k}: {done[k]['train_return_last100']:.0f}" for k in sorted(done))
            decision = "baseline" if label == "base" else decide(returns, base_returns)
            note = f"; not finished: {', '.join(left)}" if left else ""
            spread = f"{mean:.0f} +- {std:.0f}" if len(returns) > 1 else f"{mean:.0f} (one seed)"
            lines.append(f"| {label} | `{overrides(sweep, base_sweep)}` | {per_seed}{note} | {spread} | "
                         f"{mean_std(evals)[0]:.0f} | {mean_std(walls)[0]:.0f} | {decision} |")
        lines.append("")
    return "\n".join(lines)


def entry(text: str) -> tuple:
    if ":" not in text or "=" not in text.split(":", 1)[1]:
        raise ConfigError(f"{text!r}: give <env>:<label>=<sweep dir>")
    env, rest = text.split(":", 1)
    label, path = rest.split("=", 1)
    if not Path(path).is_dir():
        raise ConfigError(f"{path}: no such directory")
    return env, label, Path(path)


def main(argv=None) -> int:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("entries", nargs="+", type=entry)
    parser.add_argument("--out", type=out_file, default=None)
    args = parser.parse_args(argv)
    text = table(args.entries)
    print(text)
    if args.out:
        args.out.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(run_main(main))
