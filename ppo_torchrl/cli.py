"""`key=value` arguments for the small entry points (evaluate, export), checked like Hydra's; `run=latest`;
the commands a finished run suggests; the check that the app runs on the project's Python."""

from __future__ import annotations

import json
import os
import shlex
import sys
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.overrides import SCIENTIFIC, check_path, closest

TRUE, FALSE = {"true", "1", "yes"}, {"false", "0", "no"}
LATEST = "latest"  # run=latest: the newest run dir under OUTPUTS; run=latest/<env>: the newest of that env
OUTPUTS = Path("outputs")  # where runs go by default (conf/config.yaml: hydra.run.dir, hydra.sweep.dir)
NEEDS = ("hydra", "omegaconf", "torch", "torchrl", "gymnasium", "mujoco")  # what a wrong interpreter lacks
PATH_ARGS = ("run", "out")  # evaluate's and export's paths: checked as the training command's (overrides.check_path)
MAX_EPISODES = 10**6  # a million episodes of a thousand steps run for days: a larger count is a typo
SEED_LIMIT = 2**32  # episode i starts from seed * 1000 + i, a 32-bit seed


def parse_args(argv: list[str], spec: Dict[str, Any], usage: str, help: Optional[Dict[str, str]] = None,
               about: str = "") -> Dict[str, Any]:
    """spec: name -> default (its type is the default's; None means a required string).

    help: name -> one line of meaning; with --help or -h anywhere, print the usage page and exit 0.
    """
    if "--help" in argv or "-h" in argv:
        print_help(usage, {k: ((help or {}).get(k, ""), default) for k, default in spec.items()}, about)
    values = dict(spec)
    for arg in argv:
        key, sep, raw = arg.partition("=")
        if not sep or key not in spec:
            near = closest(key.lstrip("-"), spec) if key else None
            hint = f"; did you mean {near}={raw or '<value>'}?" if near else ""
            raise ConfigError(f"unexpected argument '{arg}'{hint}; usage: {usage}")
        default = spec[key]
        try:
            if isinstance(default, bool):
                if raw.lower() not in TRUE | FALSE:
                    raise ValueError
                values[key] = raw.lower() in TRUE
            elif isinstance(default, int):
                values[key] = int(raw) if not SCIENTIFIC.fullmatch(raw) or not float(raw).is_integer() \
                    else int(float(raw))  # episodes=1e2
            else:
                values[key] = raw
        except ValueError:
            raise ConfigError(f"{key}={raw}: expected a {type(default).__name__}; usage: {usage}") from None
        if key in PATH_ARGS and raw:  # out= empty means the default dir
            check_path(key, raw, arg)
    missing = [k for k, v in values.items() if v is None]
    if missing:
        raise ConfigError(f"missing {', '.join(k + '=...' for k in missing)}; usage: {usage}")
    return values


def whole(name: str, value, spelled: str = "") -> int:
    """A count or a seed given to the Python API as the CLI takes it: an int (or a float that is a whole number, as
    1e3); a bool, a fraction, an infinity or a string is one ConfigError line, never rounded or taken as 1."""
    import numbers

    spelled = spelled or f"{name}={value!r}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ConfigError(f"{spelled} must be a whole number (an int), not {type(value).__name__}")
    if isinstance(value, numbers.Integral):
        return int(value)
    if not (float(value).is_integer()):  # a fraction, inf or nan
        raise ConfigError(f"{spelled} must be a whole number (an int): it is not rounded")
    return int(value)


def check_episodes(episodes, seed, who: str = "") -> tuple:
    """evaluate's episodes= and seed= (the CLI's and evaluate_run()'s one check): (episodes, seed) as ints, or one
    ConfigError line: episodes in 1..MAX_EPISODES, every episode seed (seed * 1000 + i) in [0, 2^32)."""
    episodes, seed = whole("episodes", episodes, f"{who}episodes={episodes!r}"), whole("seed", seed, f"{who}seed={seed!r}")
    if episodes < 1:
        raise ConfigError(f"{who}episodes={episodes} must be >= 1")
    if episodes > MAX_EPISODES:
        raise ConfigError(f"{who}episodes={episodes} must be at most {MAX_EPISODES:,} (a million episodes of a "
                          "thousand steps run for days)")
    if not 0 <= seed * 1000 + episodes < SEED_LIMIT:
        raise ConfigError(f"{who}seed={seed} must be in 0..{(SEED_LIMIT - episodes) // 1000}: episode i starts "
                          "from seed * 1000 + i")
    return episodes, seed


def print_help(usage: str, arguments: Dict[str, Tuple[str, Any]], about: str = "") -> None:
    """The usage page of an entry point: what it does, then each argument's meaning and default."""
    lines = [f"usage: {usage}", ""] + ([about, ""] if about else []) + ["arguments:"]
    width = max(len(name) for name in arguments) + 2
    for name, (meaning, default) in arguments.items():
        shown = str(default).lower() if isinstance(default, bool) else default
        shown = "required" if default is None else "default: none" if default == "" else f"default: {shown}"
        lines.append(f"  {name:<{width}}{meaning} ({shown})")
    print("\n".join(lines))
    raise SystemExit(0)


def run(main) -> None:
    """Run an entry point's main(argv) through the one error path (errors.py), signals included."""
    from ppo_torchrl.errors import guarded
    from ppo_torchrl.run.signals import ignore_from_now, install

    def checked(argv: list[str]):
        check_interpreter()
        from ppo_torchrl.run.loggers import quiet_mujoco

        quiet_mujoco()
        return main(argv)

    install()
    try:
        guarded(checked, sys.argv[1:])
    finally:
        ignore_from_now()


def resolve_run(arg: str) -> Path:
    """A run dir argument as a path: `latest` is the newest usable run dir under outputs/ (by its summary.json,
    in a dir this app made): a finished or interrupted run before one that was killed, never one still
    training (its dir locked) or failed; a damaged summary.json is skipped with a warning line.
    `latest/<env>` is the newest of that env (summary.json's env, or its model file's name:
    latest/quadruped_step); a path that exists is itself. Says on stderr which run `latest` picked."""
    name, _, env = arg.partition("/")
    if name != LATEST or Path(arg).exists():
        return Path(arg)
    from ppo_torchrl.run.rundir import MANIFEST, in_use

    runs, envs = [], set()
    for root, dirs, files in os.walk(OUTPUTS):
        if "summary.json" not in files:
            continue
        dirs[:] = []  # a run dir holds no other run
        summary = Path(root) / "summary.json"
        if not (Path(root) / MANIFEST).is_file():
            continue
        try:
            info = json.loads(summary.read_text())
            if not isinstance(info, dict):
                raise ValueError("not a JSON object")
            frames = int(info.get("frames") or 0)
        except (OSError, ValueError, TypeError) as exc:
            print(f"warning: {arg}: skipped {summary}, which cannot be read ({exc})", file=sys.stderr, flush=True)
            continue
        label = str(info.get("env"))
        envs.add(label)
        if env and env not in (label, Path(label.partition(":")[2]).stem):
            continue
        if info.get("status") == "failed" or in_use(Path(root)):
            continue
        info["frames"] = frames
        runs.append(((info.get("status") in ("finished", "interrupted"), summary.stat().st_mtime), Path(root), info))
    if not runs:
        where = f"{OUTPUTS}/ (in {Path.cwd()})"
        if env and envs:
            raise ConfigError(f"{arg}: no run of {env} under {where}; its runs are of {', '.join(sorted(envs))}")
        raise ConfigError(f"{arg}: no run dir under {where}; give the run dir itself")
    _, run_dir, info = max(runs, key=lambda run: run[0])
    print(f"{arg}: {run_dir} ({info.get('env')}, {info.get('status')} at {info.get('frames', 0):,} frames)",
          file=sys.stderr, flush=True)
    return run_dir


def shown_path(path) -> str:
    """A path as a command shows it: relative to the working dir when inside it, else as it is."""
    relative = os.path.relpath(path) if os.path.isabs(path) else str(path)
    return relative if not relative.startswith("..") else str(path)


def python_command() -> str:
    """The interpreter running this, as a command to paste."""
    return shlex.quote(shown_path(sys.executable or "python"))


def check_interpreter() -> None:
    """The app's packages must import: a checkout's system Python has none of them (one line, exit 2)."""
    import importlib.util

    missing = next((name for name in NEEDS if importlib.util.find_spec(name) is None), None)
    if missing is None:
        return
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    module = spec.name.removesuffix(".__main__") if spec is not None else "ppo_torchrl"
    venv = Path(__file__).resolve().parent.parent / ".venv" / "bin" / "python"
    use = shlex.quote(os.path.relpath(venv)) if venv.is_file() else ".venv/bin/python (make setup makes it)"
    raise ConfigError(f"{sys.executable} has no '{missing}' package: it is not the project's Python; run "
                      f"{use} -m {module} ... (or make train)")
