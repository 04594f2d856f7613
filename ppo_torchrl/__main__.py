"""`python -m ppo_torchrl env=Hopper-v4 [overrides]`: train PPO, or sweep with `-m`.

`resume=<run dir> [collector.total_frames=N]` continues a run in its own directory. Returns the
final deterministic eval return (falling back to the last-100 training return), the value a Hydra
sweeper such as Optuna maximizes.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from ppo_torchrl.config import resume_config
from ppo_torchrl.envs import check_env_id, env_files
from ppo_torchrl.errors import ConfigError, Interrupted, TrainingError, report_and_exit

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")
HYDRA_FLAGS_WITHOUT_RUN = ("--cfg", "-c", "--help", "-h", "--hydra-help", "--info", "-i", "--version",
                           "--shell-completion", "-sc", "--resolve", "-p", "--package")


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> float:
    from ppo_torchrl import checkpoint
    from ppo_torchrl.trainer import train

    try:
        state = None
        if cfg.resume:
            run_dir = Path(cfg.resume)
            user = [o for o in HydraConfig.get().overrides.task if not o.startswith("resume=")]
            cfg = resume_config(run_dir, user)
            state = checkpoint.load(run_dir / "checkpoints" / checkpoint.LAST)
        else:
            run_dir = Path(HydraConfig.get().runtime.output_dir)
        check_env_id(cfg.env.id)
        summary = train(cfg, run_dir, state)
    except (ConfigError, TrainingError, Interrupted) as error:
        report_and_exit(error)
    for key in ("eval_return_mean", "train_return_last100"):
        if summary.get(key) is not None:
            return float(summary[key])
    return float("-inf")


def check_env_override(args: list[str]) -> None:
    """`env=<name>` must name a file in conf/env; say which exist and how to use any other id."""
    for arg in args:
        if arg.startswith("env=") and "," not in arg:
            name = arg.split("=", 1)[1]
            available = env_files()
            if name not in available:
                shown = ", ".join(n for n in available if n != "gym")
                raise ConfigError(
                    f"env={name} has no config file. Available: {shown}. "
                    f"For any other registered Gymnasium id use: env=gym env.id={name}"
                )


def check_resume(args: list[str]) -> list[str]:
    """`resume=<dir>` must be a run dir with a checkpoint; the job then runs in that dir."""
    for arg in args:
        if arg.startswith("resume="):
            run_dir = Path(arg.split("=", 1)[1]).expanduser()
            if not run_dir.is_dir():
                raise ConfigError(f"resume={run_dir}: no such directory; give the run dir of an earlier run")
            if not (run_dir / "config.yaml").is_file() or not (run_dir / "checkpoints" / "last.pt").is_file():
                raise ConfigError(f"resume={run_dir} is not a ppo_torchrl run dir: it needs config.yaml and "
                                  "checkpoints/last.pt")
            # Keep the run's own .hydra/ as it was: the saved config is the one that resumes.
            return [f"hydra.run.dir={run_dir}", "hydra.output_subdir=null"]
    return []


def check_composes(args: list[str]) -> None:
    """Compose the config as Hydra will, so a bad override is one line, not Hydra's report."""
    from hydra import compose, initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    overrides = [a for a in args if not a.startswith(("-", "hydra.", "hydra/", "+hydra", "~hydra"))]
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            compose(config_name="config", overrides=overrides)
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(one_line(exc)) from exc


def compose_with_hydra(args: list[str]):
    """The config of `args`' overrides with its hydra node (launcher, sweeper); sweeps take no part."""
    from hydra import compose, initialize_config_dir
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    try:
        parsed = OverridesParser.create().parse_overrides([a for a in args if "=" in a and not a.startswith("-")])
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            return compose(config_name="config", overrides=[o.input_line for o in parsed if not o.is_sweep_override()],
                           return_hydra_config=True)
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(one_line(exc)) from exc


def announce_study(args: list[str]) -> None:
    """`-m hparams_search=...`: say, before it starts, whether the Optuna study is new or resumed."""
    import optuna

    sweeper = compose_with_hydra(args).hydra.sweeper
    name, storage = sweeper.study_name, sweeper.storage
    if storage.startswith("sqlite:///"):  # sqlite makes the file, not its folder
        Path(storage[len("sqlite:///"):]).parent.mkdir(parents=True, exist_ok=True)
    trials = {study.study_name: study.n_trials for study in optuna.get_all_study_summaries(storage)}
    state = f"resuming study {name} with {trials[name]} trials" if name in trials else f"new study {name}"
    print(f"optuna: {state} in {storage}", file=sys.stderr, flush=True)


def dry_run(args: list[str]) -> list[str]:
    """`-m ... --cfg job|hydra|all` (or `--info`), which Hydra refuses ("Only one of --run, --multirun,
    --cfg, --info ..."): print the launcher and the jobs, and return the arguments that make Hydra
    show job #0 as the multirun would compose it."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    cfg = compose_with_hydra(args)
    overrides = [a for a in args if "=" in a and not a.startswith("-")]
    parsed = OverridesParser.create().parse_overrides(overrides)
    task = [o for o in parsed if not o.is_hydra_override()]
    sweeper = cfg.hydra.sweeper._target_
    basic = sweeper.endswith(".BasicSweeper")
    if basic and any(o.is_sweep_override() and not o.is_discrete_sweep() for o in task):
        raise ConfigError("-m sweeps over lists, choice() or range(); interval() needs hparams_search=optuna")
    print(f"# dry run of -m: launcher {cfg.hydra.launcher._target_}, sweep dir {cfg.hydra.sweep.dir}")
    if basic:
        values = [[f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()] if o.is_sweep_override()
                  else [o.input_line] for o in task]
        jobs = [list(job) for job in itertools.product(*values)]
        print(f"# {len(jobs)} job{'s' if len(jobs) > 1 else ''}:")
        for num, job in enumerate(jobs):
            print(f"#   #{num} : {' '.join(job)}")
        first = jobs[0]
    else:  # Optuna: each trial's values are chosen as the search runs
        print(f"# {sweeper.rsplit('.', 1)[-1]}: {cfg.hydra.sweeper.get('n_trials', '?')} trials, values chosen as "
              "it runs; shown: the config without them")
        first = [o.input_line for o in task if not o.is_sweep_override()]
    print(f"# job #0{'' if basic else ' (before the sweeper sets its values)'}:")
    hydra_args = [o.input_line for o in parsed if o.is_hydra_override()]
    flags = [a for a in args if a not in overrides and a not in ("-m", "--multirun")]
    return [*flags, *first, *hydra_args, "hydra.mode=MULTIRUN"]


def one_line(exc: BaseException) -> str:
    """Hydra's multi-line messages, folded: what failed, then the first line of why."""
    lines = [l.strip() for l in str(exc).splitlines() if l.strip()]
    head, options = [], []
    for line in lines:
        if line.startswith("Config search path"):
            break  # where Hydra looked: noise to a user
        (options if options or line.startswith("Available options") else head).append(line)
    message = head[0].rstrip(".") if head else type(exc).__name__
    cause = exc.__cause__
    if cause is not None and str(cause).strip():
        message += f": {str(cause).strip().splitlines()[0]}"
        key = getattr(cause, "full_key", None)
        if key and key not in message:
            message += f" (key '{key}')"
    elif len(head) > 1 and "append" not in head[1]:
        message += f": {head[1]}"
    if options:
        message += f". {options[0].rstrip(':')}: {', '.join(options[1:])}"
    return message


if __name__ == "__main__":
    argv = sys.argv[1:]
    multirun = "-m" in argv or "--multirun" in argv
    try:
        check_env_override(argv)
        sys.argv += check_resume(argv)
        runs = not any(a.split("=")[0] in HYDRA_FLAGS_WITHOUT_RUN for a in argv)
        if not multirun and runs:
            check_composes(argv)
        if multirun and runs and any(a.startswith("hparams_search=") for a in argv):
            announce_study(argv)
        if multirun and any(a.split("=")[0] in ("--cfg", "-c", "--info", "-i") for a in argv):
            sys.argv[1:] = dry_run(argv)
    except ConfigError as err:
        report_and_exit(err)
    main()
