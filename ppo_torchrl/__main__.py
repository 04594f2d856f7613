"""`python -m ppo_torchrl env=Hopper-v4 [overrides]`: train PPO, or sweep with `-m`.

`resume=<run dir> [collector.total_frames=N]` continues a run in its own directory. Returns the
final deterministic eval return (falling back to the last-100 training return), the value a Hydra
sweeper such as Optuna maximizes.

Before Hydra starts (and writes its `.hydra/` files), the command is checked whole: the config is
composed and every value validated (each job of a sweep too), and the run or sweep dir is claimed
(rundir.py). A refused command exits 2 with one line and leaves every file as it was.
"""

from __future__ import annotations

import glob
import itertools
import os
import sys
from pathlib import Path

from ppo_torchrl import signals
from ppo_torchrl.errors import ConfigError, Interrupted, guarded
from ppo_torchrl.overrides import HELP_FLAGS, INFO_FLAGS, check_env_override, key_hint, split_args, whole_counts

if __name__ == "__main__":
    signals.install()  # from here on a Ctrl-C or SIGTERM is one line and exit 130 / 143, imports included

CONF_DIR = str(Path(__file__).resolve().parent.parent / "conf")
# Keys whose value is a path: passed to Hydra through an environment variable, so any character a path
# may hold (a quote, a space, non-ASCII) reaches the app as typed, run after run and on resume.
PATH_KEYS = ("resume", "init_from", "hydra.run.dir", "hydra.sweep.dir")
PATH_ENV = "PPO_TORCHRL_PATH_{}"
# A sweep job's dir is <num>_<the overrides that vary> (conf/config.yaml: hydra.sweep.subdir); prepare() tells
# Hydra which keys do not vary through this list.
EXCLUDE_KEYS = "hydra.job.config.override_dirname.exclude_keys"
SWEEP = {}  # the sweep dir this command claimed (prepare), for the line that ends the sweep


def main(cfg) -> float:
    """The Hydra task function: one training run in its (already claimed) run dir, or with `trial_seeds`
    one run per seed in its seed<k>/ folder, whose objectives are averaged."""
    return guarded(_run_job, cfg)


def objective(summary: dict) -> float:
    """What a sweeper maximizes: the final deterministic eval return, else the last-100 training return."""
    for key in ("eval_return_mean", "train_return_last100"):
        if summary.get(key) is not None:
            return float(summary[key])
    return float("-inf")


def _run_job(cfg) -> float:
    from hydra.core.hydra_config import HydraConfig

    from ppo_torchrl import checkpoint, rundir
    from ppo_torchrl.config import resume_config
    from ppo_torchrl.trainer import train

    state = None
    if cfg.resume:
        run_dir = Path(cfg.resume)
        state = checkpoint.load(run_dir / "checkpoints" / checkpoint.LAST)
        user = [o for o in HydraConfig.get().overrides.task if not o.startswith("resume=")]
        cfg = resume_config(run_dir, user, state)
    else:
        run_dir = Path(HydraConfig.get().runtime.output_dir)
    # A single run's dir was claimed before Hydra started; a sweep's jobs claim theirs here.
    multirun = HydraConfig.get().mode.name == "MULTIRUN"
    rundir.claim(run_dir, resume=bool(cfg.resume), what="job" if multirun else "run")
    try:
        if cfg.trial_seeds:
            return _run_seeds(cfg, run_dir)
        return objective(train(cfg, run_dir, state, next_steps=not multirun))  # a sweep ends with its report command
    except (Interrupted, KeyboardInterrupt):
        if multirun:
            fail_running_trial(HydraConfig.get().sweeper)
        raise
    finally:
        rundir.rollback(run_dir)  # a job refused before it started training leaves its dir as it was


def fail_running_trial(sweeper) -> None:
    """A signal in a trial of a stored Optuna study: the study's running trial (this job's: the sweeper runs one
    at a time) is marked failed now, so the stored study never shows it running."""
    storage, name = sweeper.get("storage"), sweeper.get("study_name")
    if not (storage and name and "optuna" in str(sweeper.get("_target_", ""))):
        return
    import optuna

    study = optuna.load_study(study_name=name, storage=storage)
    for trial in study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,)):
        study.tell(trial.number, state=optuna.trial.TrialState.FAIL)


def _run_seeds(cfg, run_dir: Path) -> float:
    """trial_seeds=[6,7,8]: train each seed in turn into run_dir/seed<k>/ (an ordinary run dir each) and
    return the mean of their objectives; trial.json holds the per-seed figures as they come. A seed below
    trial_prune_below ends the trial there (trial.json: "pruned": true)."""
    import copy
    import statistics

    from ppo_torchrl import rundir
    from ppo_torchrl.trainer import train

    rundir.commit(run_dir)  # the trial's dir is the seed runs' parent: a seed stopped midway keeps its files
    seeds, values = list(cfg.trial_seeds), []
    for seed in seeds:
        seed_cfg = copy.deepcopy(cfg)
        seed_cfg.seed, seed_cfg.trial_seeds, seed_cfg.trial_prune_below = seed, [], None
        seed_dir = run_dir / f"seed{seed}"
        rundir.claim(seed_dir)
        try:
            values.append(objective(train(seed_cfg, seed_dir, None, next_steps=False)))
        finally:
            rundir.rollback(seed_dir)
        mean = statistics.fmean(values)
        pruned = cfg.trial_prune_below is not None and values[-1] < cfg.trial_prune_below and seed != seeds[-1]
        rundir.atomic_write_json(run_dir / "trial.json", {
            "seeds": seeds[:len(values)], "objective": values, "mean": mean,
            "std": statistics.stdev(values) if len(values) > 1 else 0.0, "pruned": pruned})
        rundir.record(run_dir)
        if pruned:
            break
    note = f" (pruned: seed {seeds[len(values) - 1]} below {cfg.trial_prune_below:g})" if pruned else ""
    print(f"trial: seeds {', '.join(map(str, seeds[:len(values)]))}: {', '.join(f'{v:.1f}' for v in values)}; "
          f"mean {mean:.1f}{note}", file=sys.stderr, flush=True)
    return mean


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError):
        return ""


def check_resume(resume: str, overrides: list[str]) -> Path:
    """`resume=<dir>` must be a run dir with a checkpoint that has frames left to train."""
    from ppo_torchrl import checkpoint
    from ppo_torchrl.config import resume_config
    from ppo_torchrl.rundir import ASIDE, shipped
    from ppo_torchrl.validation import check_frames_left, validate_config

    run_dir = Path(resume).expanduser()
    if not run_dir.is_dir():
        moved = sorted(run_dir.parent.glob(f"{glob.escape(run_dir.name)}{ASIDE}*")) if run_dir.parent.is_dir() else []
        hint = (f"; overwrite=true moved the run that was there to {moved[-1]}: resume={moved[-1]}" if moved
                else "; give the run dir of an earlier run")
        raise ConfigError(f"resume={run_dir}: no such directory{hint}")
    if shipped(run_dir):
        raise ConfigError(f"resume={run_dir}: a shipped zoo policy is read-only; train on from it in a dir of your own "
                          f"with init_from={run_dir}")
    if not (run_dir / "checkpoints" / "last.pt").is_file():
        stopped = [d for d in sorted(run_dir.glob("seed*")) if (d / "checkpoints" / "last.pt").is_file()
                   and '"status": "finished"' not in _read(d / "summary.json")]
        if (run_dir / "trial.json").is_file() or stopped:  # a trial_seeds run: its seeds are runs of their own
            then = (f"resume={stopped[0]} continues its stopped seed" if stopped else "its seeds are all finished")
            raise ConfigError(f"resume={run_dir} is a trial of several seeds (trial.json), each seed a run of its own: "
                              f"{then}; overwrite=true starts the trial again")
        raise ConfigError(f"resume={run_dir} is not a ppo_torchrl run dir with a checkpoint: it needs "
                          "checkpoints/last.pt")
    state = checkpoint.load(run_dir / "checkpoints" / checkpoint.LAST)
    cfg = resume_config(run_dir, [o for o in overrides if not o.startswith("resume=")], state, announce=True)
    validate_config(cfg)
    check_frames_left(run_dir, state["frames"], cfg.collector.total_frames)
    return run_dir


def run_name(experiment, env_choice, env_id, xml_file) -> str:
    """What a run dir is named by (conf/config.yaml: hydra.run.dir): the preset, else the env file
    (quadruped_step), else for env=gym the id; a model file given to env=mjcf adds its stem, to env=legged
    (or a scene.xml to env=mjcf) the model's name (legged_trot_go1, go1: not scene)."""
    robot = None
    if xml_file and env_choice == "mjcf" and Path(str(xml_file)).stem != "scene":
        robot = Path(str(xml_file)).stem
    elif xml_file and env_choice in ("mjcf", "legged"):
        from ppo_torchrl.envs import resolve_model_file
        from ppo_torchrl.robots.model import robot_label

        try:
            robot = robot_label(resolve_model_file(str(xml_file)))
        except ConfigError:  # no such file: the config check says so, with its reason
            robot = Path(str(xml_file)).stem
    if experiment is not None:
        return f"{experiment}_{robot}" if robot and env_choice == "legged" else str(experiment)
    if env_choice == "gym":
        return str(env_id)
    return robot or str(env_choice)


def register_resolvers() -> None:
    from omegaconf import OmegaConf

    import ppo_torchrl.config  # noqa: F401  (registers the schemas and their resolvers)

    OmegaConf.register_new_resolver("ppo.run_name", run_name, replace=True)


def compose(overrides: list[str], with_hydra: bool = False):
    """The config as Hydra will compose it (with its hydra node: launcher, sweeper, dirs, if asked);
    a bad override is one line, not Hydra's report."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir
    from hydra.errors import HydraException
    from omegaconf.errors import OmegaConfBaseException

    register_resolvers()

    if not with_hydra:
        overrides = [a for a in overrides if not a.lstrip("+~").startswith(("hydra.", "hydra/"))]
    try:
        with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
            return hydra_compose(config_name="config", overrides=overrides, return_hydra_config=with_hydra)
    except (HydraException, OmegaConfBaseException) as exc:
        raise ConfigError(one_line(exc) + unknown_key_hint(exc, overrides)) from exc


def unknown_key_hint(exc: BaseException, overrides: list[str]) -> str:
    """`; did you mean collector.total_frames?` for a key the config does not have."""
    import re

    found = re.search(r"override '([^']+)'", str(exc)) or re.search(r"Key '([^']+)' (?:is )?not in", str(exc))
    if not found:
        return ""
    groups = [o for o in overrides if "=" in o and "." not in o.partition("=")[0] and "/" not in o]
    if groups == overrides:  # the groups alone failed: nothing to compare the key with
        return ""
    try:
        return key_hint(found.group(1), compose(groups))
    except ConfigError:
        return ""


def hydra_value(cfg, key: str):
    """A value of the composed hydra node (e.g. hydra.run.dir); an interpolation that fails is one line."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        return OmegaConf.select(cfg, key, throw_on_missing=True)
    except OmegaConfBaseException as exc:
        raise ConfigError(f"{key}: {str(exc).splitlines()[0]}; fix the value given to {key}") from None


def sweep_jobs(overrides: list[str], covering: bool = False) -> list[list[str]]:
    """The override lists of a sweep's jobs (discrete sweeps expanded; an interval is left to the sweeper).
    covering: each value of each discrete sweep once, the others at their first value (the first job first) -- what
    to check of a space a sampler draws from (Optuna): its product can be a thousand configs, a minute to compose
    each hundred, and the sampler runs only some of them."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except HydraException as exc:
        raise ConfigError(one_line(exc)) from exc
    axes = []
    for arg, override in zip(overrides, parsed):
        if override.is_hydra_override():
            continue
        if not override.is_sweep_override():
            axes.append([arg])
        elif override.is_discrete_sweep():
            key = override.get_key_element()
            axes.append([f"{key}={value}" for value in override.sweep_string_iterator()])
    if covering:
        first = [axis[0] for axis in axes]
        return [first] + [first[:i] + [value] + first[i + 1:] for i, axis in enumerate(axes) for value in axis[1:]]
    return [list(job) for job in itertools.product(*axes)]


def hydra_overrides(overrides: list[str]) -> list[str]:
    return [o for o in overrides if o.lstrip("+~").startswith(("hydra.", "hydra/"))]


def announce_study(hydra_cfg, overrides: list[str]) -> None:
    """`-m hparams_search=...`: say, before it starts, whether the Optuna study is new or resumed. The space
    it searches is the sweeper's params with the command's own overrides over them, as the sweeper reads it."""
    import optuna

    sweeper = hydra_cfg.hydra.sweeper
    name, storage = sweeper.study_name, sweeper.storage
    if storage.startswith("sqlite:///"):  # sqlite makes the file, not its folder
        Path(storage[len("sqlite:///"):]).parent.mkdir(parents=True, exist_ok=True)
    if int(sweeper.get("n_trials", 1)) < 1:
        raise ConfigError(f"hydra.sweeper.n_trials={sweeper.n_trials} must be >= 1")
    trials = {study.study_name: study.n_trials for study in optuna.get_all_study_summaries(storage)}
    state = f"resuming study {name} with {trials[name]} trials" if name in trials else f"new study {name}"
    if name in trials:
        hydra = set(hydra_overrides(overrides))
        space = [f"{key}={value}" for key, value in (sweeper.params or {}).items()]
        space += [o for o in overrides if o not in hydra]
        state += check_stored_study(optuna.load_study(study_name=name, storage=storage), space)
    print(f"optuna: {state} in {storage}", file=sys.stderr, flush=True)


def check_stored_study(study, space: list[str]) -> str:
    """A stored study must search the space the command gives (`key=choice(...)` overrides, the last of a key
    wins; Optuna would fail in the first trial and leave it RUNNING); trials an interrupted sweep left RUNNING
    are marked failed. Returns what it did, for the line."""
    import optuna

    from hydra_plugins.hydra_optuna_sweeper._impl import create_params_from_overrides

    wanted, _ = create_params_from_overrides(space)
    trials = study.get_trials(deepcopy=False)
    for trial in trials:
        for key, distribution in trial.distributions.items():
            if key in wanted and wanted[key] != distribution:
                raise ConfigError(f"optuna study {study.study_name} searched {key} over {distribution}, this command "
                                  f"over {wanted[key]}; keep the stored space or name a new study with "
                                  "hydra.sweeper.study_name=<name>")
    stale = [t for t in trials if t.state == optuna.trial.TrialState.RUNNING]
    for trial in stale:
        study.tell(trial.number, state=optuna.trial.TrialState.FAIL)
    return f" ({len(stale)} left running by an interrupted sweep marked failed)" if stale else ""


def show_job(job: list[str], resolve: bool) -> None:
    """`--cfg job`: the composed config as Hydra prints it, less the keys the chosen env, loss and advantage
    do not read (a first comment line names them); then exit 0."""
    from omegaconf import OmegaConf, open_dict, read_write
    from omegaconf.errors import OmegaConfBaseException

    from ppo_torchrl.startup import not_applicable

    cfg = compose(job)
    hidden = not_applicable(cfg)
    for key in hidden:
        parent, _, leaf = key.rpartition(".")
        node = OmegaConf.select(cfg, parent)
        with read_write(node), open_dict(node):
            del node[leaf]
    names = ", ".join(f"{key}.*" if key.startswith("env.") else key for key in hidden)
    try:
        text = OmegaConf.to_yaml(cfg, resolve=resolve)
    except OmegaConfBaseException as exc:  # an interpolation that fails with --resolve
        raise ConfigError(one_line(exc)) from exc
    left_out = f"# left out, as this env, loss and advantage do not read them: {names}\n" if hidden else ""
    sys.stdout.write(left_out + text)  # one write: a reader that stops early (| head) gets no broken pipe mid-way
    raise SystemExit(0)


def job_dirs(overrides: list[str], basic: bool) -> list[str]:
    """Hydra overrides that name each sweep job's dir by the overrides that vary (conf/config.yaml:
    hydra.sweep.subdir): the keys given one value are excluded. With none that varies, and for an Optuna
    trial (values of many digits, in the study and the job's .hydra/overrides.yaml), the job number alone."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    if {o.split("=", 1)[0].lstrip("+~") for o in hydra_overrides(overrides)} & {"hydra.sweep.subdir", EXCLUDE_KEYS}:
        return []  # the user's own
    parsed = [o for o in OverridesParser.create().parse_overrides(overrides) if not o.is_hydra_override()]
    if not basic or not any(o.is_sweep_override() for o in parsed):
        return ["hydra.sweep.subdir=${hydra.job.num}"]
    fixed = [repr(o.key_or_group) for o in parsed if not o.is_sweep_override()]
    return [f"{EXCLUDE_KEYS}=[{','.join(fixed)}]"]


def dry_run(flags: list[str], overrides: list[str], cfg) -> list[str]:
    """`-m ... --cfg job|hydra|all` (or `--info`), which Hydra refuses ("Only one of --run, --multirun,
    --cfg, --info ..."): print the launcher and the jobs, and return the arguments that make Hydra
    show job #0 as the multirun would compose it (cfg: job #0's config with its hydra node)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    jobs = sweep_jobs(overrides)
    sweeper = cfg.hydra.sweeper._target_
    basic = sweeper.endswith(".BasicSweeper")
    parsed = OverridesParser.create().parse_overrides(overrides)
    if basic and any(o.is_sweep_override() and not o.is_discrete_sweep() for o in parsed):
        raise ConfigError("-m sweeps over lists, choice() or range(); interval() needs hparams_search=optuna")
    print(f"# dry run of -m: launcher {cfg.hydra.launcher._target_}, sweep dir {cfg.hydra.sweep.dir}")
    if basic:
        print(f"# {len(jobs)} job{'s' if len(jobs) > 1 else ''}:")
        for num, job in enumerate(jobs):
            print(f"#   #{num} : {' '.join(job)}")
    else:  # Optuna: each trial's values are chosen as the search runs
        print(f"# {sweeper.rsplit('.', 1)[-1]}: {cfg.hydra.sweeper.get('n_trials', '?')} trials, values chosen as "
              "it runs; shown: the config without them")
    print(f"# job #0{'' if basic else ' (before the sweeper sets its values)'}:")
    shown = [f for f in flags if f not in ("-m", "--multirun")]
    return [*shown, *jobs[0], *hydra_overrides(overrides), "hydra.mode=MULTIRUN"]


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
    """Path-valued overrides go to Hydra through environment variables (PATH_KEYS)."""
    out = []
    for arg in argv:
        key, sep, value = arg.partition("=")
        if sep and key in PATH_KEYS and "${" not in value:  # an interpolation (${now:...}) stays Hydra's
            arg = path_override(key, unquote(value))
        out.append(arg)
    return out


def with_override(argv: list[str], key: str, value) -> list[str]:
    return [a for a in argv if not a.startswith(f"{key}=")] + [path_override(key, value)]


def prepare(argv: list[str]) -> list[str]:
    """Check the whole command and claim its dir; returns the argv Hydra runs with."""
    from ppo_torchrl import rundir
    from ppo_torchrl.validation import validate_config

    flags, overrides = split_args(argv)
    if any(f in HELP_FLAGS for f in flags):
        return argv
    resume = next((unquote(o.split("=", 1)[1]) for o in overrides if o.startswith("resume=")), None)
    argv, overrides = route_paths(argv), route_paths(overrides)
    check_env_override(overrides)
    argv, overrides = whole_counts(argv, overrides, compose)  # collector.total_frames=1e6: the int it is
    multirun = "-m" in flags or "--multirun" in flags
    jobs = sweep_jobs(overrides) if multirun else [overrides]
    hydra_cfg = compose(jobs[0] + hydra_overrides(overrides), with_hydra=True) if multirun else None
    basic = multirun and hydra_cfg.hydra.sweeper._target_.endswith(".BasicSweeper")
    if multirun and not basic:  # a sampler's space: every value checked, not every combination
        jobs = sweep_jobs(overrides, covering=True)
    if any(f in INFO_FLAGS for f in flags):  # print or inspect: check the config, write nothing
        for job in jobs:
            compose(job)
        shown = dry_run(flags, overrides, hydra_cfg) if multirun else argv
        cfg_type = next((flags[i + 1] for i, f in enumerate(flags[:-1]) if f in ("--cfg", "-c")), None)
        if cfg_type == "job" and not {"--package", "-p", "--info", "-i"} & set(flags):
            show_job(jobs[0], resolve="--resolve" in flags)
        return shown
    if resume and not multirun:
        run_dir = check_resume(resume, overrides)
        rundir.claim(run_dir, resume=True)
        # Keep the run's own .hydra/ as it was: the saved config is the one that resumes.
        return with_override(argv, "hydra.run.dir", run_dir) + ["hydra.output_subdir=null"]
    for job in jobs:  # every job, before the first one runs (the env is built once per env config)
        validate_config(compose(job))
    if hydra_cfg is None:  # a single run's (a resume has returned above: it keeps its run's own config)
        hydra_cfg = compose(overrides, with_hydra=True)
    overwrite = bool(hydra_cfg.get("overwrite", False))
    if multirun:
        if any(o.startswith("hparams_search=") for o in overrides):
            announce_study(hydra_cfg, overrides)
        sweep_dir = Path(hydra_value(hydra_cfg, "hydra.sweep.dir"))
        rundir.claim(sweep_dir, overwrite=overwrite, what="sweep")
        SWEEP["dir"] = sweep_dir
        return with_override(argv, "hydra.sweep.dir", sweep_dir) + job_dirs(overrides, basic)
    run_dir = Path(hydra_value(hydra_cfg, "hydra.run.dir"))
    rundir.claim(run_dir, overwrite=overwrite)
    signals.ON_DISK.run_dir = run_dir
    return with_override(argv, "hydra.run.dir", run_dir)


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


def sweep_done(sweep_dir: Path) -> str:
    """The line that ends a sweep: how many runs finished, where, and the command that compares them."""
    import json
    import shlex

    from ppo_torchrl.cli import python_command, shown_path

    statuses = []
    for summary in sorted([*sweep_dir.glob("*/summary.json"), *sweep_dir.glob("*/seed*/summary.json")]):  # trial_seeds
        try:
            statuses.append(json.loads(summary.read_text()).get("status"))
        except (OSError, ValueError, AttributeError):
            statuses.append(None)
    shown = shown_path(sweep_dir)
    return (f"sweep: {statuses.count('finished')} of {len(statuses)} runs finished in {shown}; compare them: "
            f"{python_command()} -m ppo_torchrl.report {shlex.quote(shown)}")


def cli() -> None:
    from ppo_torchrl.cli import check_interpreter

    check_interpreter()  # the system Python of a checkout: one line that names the right one
    import hydra

    from ppo_torchrl import rundir
    from ppo_torchrl.loggers import quiet_mujoco

    quiet_mujoco()  # from the first model the command's check compiles

    register_resolvers()
    sys.argv = [sys.argv[0]] + prepare(sys.argv[1:])
    try:
        hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")(main)()
    finally:  # a sweep dir whose every job was refused, or a run stopped before it started: as it was
        rundir.finish()
    if SWEEP:
        print(sweep_done(SWEEP["dir"]), file=sys.stderr, flush=True)


if __name__ == "__main__":
    guarded(cli)
