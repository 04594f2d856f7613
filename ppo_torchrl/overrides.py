"""The training command's words, checked before Hydra sees them: Hydra's flags apart from the key=value
overrides, and the mistakes a user of SB3, rl-zoo or CleanRL makes on the way in, each one line with
the fix: `--env Hopper-v4` (overrides are key=value), `env=Hoper-v4` (the closest env file or
Gymnasium id), `colector.total_frames=1000` (the closest key at that level of the config), and counts
written `1e6` or `2e4` (taken as the integers they are where the config wants an int).
"""

from __future__ import annotations

import difflib
import errno
import os
import re
from typing import Optional

from ppo_torchrl.conf_files import env_files
from ppo_torchrl.errors import ConfigError

# Hydra flags that print or inspect instead of running a job; those marked take a value.
HELP_FLAGS = ("--help", "-h", "--hydra-help", "--version", "--shell-completion", "-sc")
INFO_FLAGS = ("--cfg", "-c", "--info", "-i", "--resolve")
VALUE_FLAGS = ("--cfg", "-c", "--package", "-p", "--config-path", "-cp", "--config-name", "-cn",
               "--config-dir", "-cd", "--experimental-rerun")
INFO_VALUES = ("all", "config", "defaults", "defaults-tree", "plugins", "searchpath")
RUN_FLAGS = ("-m", "--multirun", "--run", "-r")
# Other tools' argument names and this app's key for them (SB3 / rl-zoo / CleanRL).
# (No `algo`: this app is PPO; `--algo ppo` is answered by ALGO, never with another algorithm's loss.)
HABITS = {"env_id": "env", "total_timesteps": "collector.total_frames", "n_timesteps": "collector.total_frames",
          "total_frames": "collector.total_frames", "num_envs": "collector.num_envs", "n_envs": "collector.num_envs",
          "learning_rate": "optim.lr", "n_steps": "collector.frames_per_batch", "n_epochs": "loss.epochs",
          "update_epochs": "loss.epochs", "batch_size": "loss.minibatch_size", "gamma": "advantage.gamma",
          "gae_lambda": "advantage.lmbda", "ent_coef": "loss.entropy_coef", "clip_range": "loss.clip_epsilon",
          "clip_coef": "loss.clip_epsilon", "cuda": "device", "track": "logger", "capture_video": "eval.video"}
# Keys whose value is a path: passed to Hydra through an environment variable, so any character a path
# may hold (a quote, a space, non-ASCII) reaches the app as typed, run after run and on resume.
PATH_KEYS = ("resume", "init_from", "hydra.run.dir", "hydra.sweep.dir")
# A model file's path goes the same way when Hydra's lexer would refuse it (a space, a non-ASCII letter, a quote): a
# plain path, or a sweep's list of them (`-m env.xml_file=a.xml,b.xml`), stays Hydra's.
MODEL_KEYS = ("env.xml_file",)
PLAIN = re.compile(r"[A-Za-z0-9_./~+:@%-]*")
PATH_ENV = "PPO_TORCHRL_PATH_{}"
SCIENTIFIC = re.compile(r"[+]?\d+(?:\.\d*)?[eE][+]?\d+")  # 1e6, 2.5e5, 1E+6: a count if it is a whole number


def split_args(argv: list[str]) -> tuple[list[str], list[str]]:
    """(Hydra flags with their values, key=value overrides). A flag Hydra does not have is the
    `--key value` habit of other tools: one line that gives the override to write instead."""
    flags, overrides, i = [], [], 0
    while i < len(argv):
        arg, following = argv[i], argv[i + 1] if i + 1 < len(argv) else None
        takes_value = arg in VALUE_FLAGS or (arg in ("--info", "-i") and following in INFO_VALUES)
        if arg.startswith("-") and arg not in (*HELP_FLAGS, *INFO_FLAGS, *VALUE_FLAGS, *RUN_FLAGS):
            key, _, value = arg.lstrip("-").partition("=")
            if not value and following is not None and "=" not in following and not following.startswith("-"):
                value = following
            name = key.replace("-", "_")
            if name == "algo":
                raise ConfigError(f"{arg}{' ' + following if value == following else ''}: {algo_line()}")
            example = f"{HABITS.get(name, name)}={value or '<value>'}"
            raise ConfigError(f"{arg}{' ' + following if value == following else ''}: the app takes key=value "
                              f"overrides, not --key value; write {example} (python -m ppo_torchrl --help lists them)")
        if arg.startswith("-"):
            flags += [arg, following] if takes_value else [arg]
        else:
            overrides.append(arg)
        i += 2 if arg.startswith("-") and takes_value else 1
    return flags, overrides


EMPTY_MEANS = {"resume": "a new run would start", "init_from": "the run would train from scratch",
               "hydra.run.dir": "the run would go to the working dir", "hydra.sweep.dir": "the sweep would go to "
               "the working dir"}


def key_of(arg: str) -> str:
    """An override's key without Hydra's prefixes (`+`, `++`, `~`)."""
    return arg.partition("=")[0].lstrip("+~")


def plain_keys(overrides: list[str]) -> list[str]:
    """`++key=value` (Hydra's add-or-override) as `key=value` for the app's keys: every key of the schema is in the
    config already, so `++` adds nothing there, and each check below sees the key as written (`++resume=<dir>`,
    `++seed=-1`). Hydra's own `hydra.*` keys keep it (a new key of hydra.job.env_set needs it), the path keys aside."""
    out = []
    for arg in overrides:
        key, sep, value = arg.partition("=")
        name = key.lstrip("+")
        if sep and key.startswith("++") and (not name.startswith(("hydra.", "hydra/")) or name in PATH_KEYS):
            arg = f"{name}={value}"
        out.append(arg)
    return out


def check_path(name: str, value, spelled: str, give: Optional[str] = None) -> None:
    """A path a command takes (PATH_KEYS; the API's run_dir= and resume=; evaluate's and export's run= and out=): one
    ConfigError line when it is empty (an unset shell variable, `resume=$RUN`) or goes through a loop of symlinks
    (`ln -s loop loop`: Python's resolve() raises RuntimeError there, which read as an internal error)."""
    text = str(value)
    if not text.strip():
        what = "<run dir>" if name == "resume" else "<run dir or checkpoint>" if name == "init_from" else "<dir>"
        raise ConfigError(f"{spelled}: the value is empty (an unset shell variable?) and "
                          f"{EMPTY_MEANS.get(name, 'there is nothing to read')}; "
                          f"{give or f'give {name}={what}, or leave {name}= out'}")
    try:
        os.stat(os.path.expanduser(text))
        looped = False
    except OSError as exc:
        looped = exc.errno == errno.ELOOP
    if looped:
        raise ConfigError(f"{spelled}: the path goes through a loop of symbolic links (a link that leads back to "
                          "itself); give a path without it")


def check_values(overrides: list[str]) -> None:
    """What Hydra would take without a word: a path key with nothing after '=' (an unset shell variable,
    `resume=$RUN`) or through a loop of symlinks, and `~key`, which deletes a key the app reads (Hydra's `~` is
    for defaults lists)."""
    for arg in overrides:
        key, sep, value = arg.partition("=")
        if sep and key.lstrip("+") in PATH_KEYS:
            check_path(key.lstrip("+"), unquote(value), arg)
        if key.startswith("~") and not key.lstrip("~").startswith(("hydra.", "hydra/")):
            name = key.lstrip("~")
            raise ConfigError(f"{arg}: '~' deletes {name}, which the app reads; set it instead ({name}=<value>), or "
                              "leave it out for its default (python -m ppo_torchrl --cfg job shows them)")


def checked_overrides(overrides: list[str], compose) -> list[str]:
    """The checks of the training command's key=value overrides before anything is composed, one set for the CLI
    (__main__.prepare) and the Python API (api.train): `++` read as plain for the app's keys, empty paths, symlink
    loops and `~key` refused, paths handed to Hydra as typed (route_paths), `env=` a file in conf/env (the closest
    named), counts written 1e6 taken as the integers they are. `compose` gives the config of some overrides."""
    overrides = plain_keys(overrides)
    check_values(overrides)
    overrides = route_paths(overrides)
    check_env_override(overrides)
    return whole_counts(overrides, overrides, compose)[1]


def algo_line() -> str:
    """What `--algo ppo` (SB3's, rl-zoo's word) is told: there is no algorithm to choose, only PPO's loss."""
    from ppo_torchrl.rl.losses import LOSSES

    return ("this app is PPO already (clipped PPO: the default loss=clip_ppo), there is no algorithm to choose; "
            f"loss= picks the loss, one of {', '.join(LOSSES)} (loss=ppo is PPO without clipping)")


def habit_hint(word: str, cfg) -> str:
    """For a top-level key the config lacks: another tool's word (total_timesteps, n_envs) or a key of a group
    written without it (total_frames): `; did you mean collector.total_frames?`; '' when neither."""
    if word == "algo":
        return f"; {algo_line()}"
    found = []
    for group in cfg.keys():
        try:
            node = cfg.get(group)
            if hasattr(node, "keys") and word in node:
                found.append(f"{group}.{word}")
        except Exception:  # noqa: BLE001 - a value that cannot be read here is no group
            continue
    if len(found) == 1:
        return f"; did you mean {found[0]}?"
    return f"; did you mean {HABITS[word]}? ({word} is another tool's word for it)" if word in HABITS else ""


def closest(word: str, known) -> Optional[str]:
    """The known name nearest to `word` (case aside), or None when nothing is near."""
    lowered = {str(k).lower(): str(k) for k in known}
    found = difflib.get_close_matches(word.lower(), list(lowered), n=1, cutoff=0.6)
    return lowered[found[0]] if found else None


def check_env_override(overrides: list[str]) -> None:
    """`env=<name>` must name a file in conf/env: the closest file (or registered Gymnasium id) is named."""
    for arg in overrides:
        if arg.startswith("env="):
            available = env_files()
            for name in arg.split("=", 1)[1].split(","):
                if name not in available:
                    raise ConfigError(f"env={name} has no config file{env_hint(name, available)}")


def env_hint(name: str, available: list[str]) -> str:
    import gymnasium as gym

    from ppo_torchrl.envs.playground import playground_hint

    files = [n for n in available if n != "gym"]
    if name in gym.registry:
        return f"; {name} is a Gymnasium id: env=gym env.id={name}"
    if playground_hint(name):
        return playground_hint(name)
    near = closest(name, files + [i for i in gym.registry if "-v" in i and i not in files])
    if near is not None:
        return f"; did you mean env={near}?" if near in files else f"; did you mean env=gym env.id={near}?"
    return f". Available: {', '.join(files)}; any other registered Gymnasium id: env=gym env.id=<id>"


def key_hint(key: str, cfg) -> str:
    """For a key the config does not have: `; did you mean collector.total_frames?` (the closest name at
    the level where the key first leaves the config), or '' when nothing is near."""
    from omegaconf import DictConfig

    node, path = cfg, []
    for part in key.lstrip("+~").split("."):
        if not isinstance(node, DictConfig):
            return ""
        if part not in node:
            habit = habit_hint(part, node) if not path else ""
            if habit:
                return habit
            near = closest(part, list(node.keys()))
            rest = key.lstrip("+~").split(".")[len(path) + 1:]
            return f"; did you mean {'.'.join([*path, near, *rest])}?" if near else ""
        node, path = node.get(part), [*path, part]
    return ""


def whole_counts(argv: list[str], overrides: list[str], compose) -> tuple[list[str], list[str]]:
    """`collector.total_frames=1e6` -> `collector.total_frames=1000000` where the config holds an int there
    (rl-zoo's habit); a sweep's values too (`=1e5,2e5`). Anything else is left for Hydra to judge.
    Returns (argv, overrides) with those values rewritten; `compose` gives the config of some overrides."""
    from omegaconf import DictConfig, OmegaConf

    written = [o for o in overrides if SCIENTIFIC.search(o.partition("=")[2])
               and not o.startswith(("hydra.", "hydra/"))]
    if not written:
        return argv, overrides
    cfg = compose([o for o in overrides if o.startswith(("env=", "experiment="))])
    rewritten = {}
    for arg in written:
        key, _, value = arg.partition("=")
        parent, _, leaf = key.lstrip("+~").rpartition(".")
        try:
            holder = OmegaConf.select(cfg, parent) if parent else cfg
            is_int = isinstance(holder, DictConfig) and OmegaConf.get_type(holder, leaf) is int  # (an int now)
        except Exception:  # noqa: BLE001 - not a key of the config: Hydra says so
            is_int = False
        if is_int:
            rewritten[arg] = f"{key}={','.join(_whole(v) for v in value.split(','))}"
    return [rewritten.get(a, a) for a in argv], [rewritten.get(o, o) for o in overrides]


def _whole(value: str) -> str:
    if SCIENTIFIC.fullmatch(value.strip()):
        number = float(value)
        if number.is_integer():
            return str(int(number))
    return value


def path_override(key: str, value) -> str:
    """`key=${oc.env:...}`: the path as typed, whatever characters it holds (see PATH_KEYS)."""
    name = PATH_ENV.format(key.replace(".", "_").upper())
    os.environ[name] = str(value)
    return f"{key}=${{oc.env:{name}}}"


def unquote(value: str) -> str:
    """A value the user quoted for Hydra ('...' or "..."), as the path it names."""
    if len(value) >= 2 and value[0] == value[-1] and value[0] in "'\"":
        return value[1:-1].replace("\\" + value[0], value[0])
    return value


def route_paths(argv: list[str]) -> list[str]:
    """Path-valued overrides go to Hydra through environment variables (PATH_KEYS; MODEL_KEYS when Hydra's lexer
    would refuse the path as typed)."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if sep and key in PATH_KEYS and "${" not in value:  # an interpolation (${now:...}) stays Hydra's
            arg = path_override(key, unquote(value))
        elif sep and key in MODEL_KEYS and "${" not in value and "," not in value and not PLAIN.fullmatch(value):
            arg = path_override(key, unquote(value))
        out.append(arg)
    return out


def with_override(argv: list[str], key: str, value) -> list[str]:
    return [a for a in argv if not a.startswith(f"{key}=")] + [path_override(key, value)]
