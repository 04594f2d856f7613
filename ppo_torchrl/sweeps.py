"""`-m`: sweeps, Optuna studies and trials of several seeds. Before Hydra runs (__main__.prepare): each
job's overrides, the dirs the jobs get, a stored study checked against the space asked, a dry run
(`-m ... --cfg job`). As the jobs run: what a sweeper maximizes (`objective`), a trial's seeds one after
the other (`run_seeds`), an interrupted trial marked failed. At the end, the line with the report command.
"""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

from ppo_torchrl.compose import one_line
from ppo_torchrl.errors import ConfigError

# A sweep job's dir is <num>_<the overrides that vary> (conf/config.yaml: hydra.sweep.subdir); prepare() tells
# Hydra which keys do not vary through this list.
EXCLUDE_KEYS = "hydra.job.config.override_dirname.exclude_keys"


def objective(summary: dict) -> float:
    """What a sweeper maximizes: the final deterministic eval return, else the last-100 training return."""
    for key in ("eval_return_mean", "train_return_last100"):
        if summary.get(key) is not None:
            return float(summary[key])
    return float("-inf")


def stored_study(sweeper):
    """A job's hydra.sweeper config: {storage, study_name} of its stored Optuna study, else None."""
    storage, name = sweeper.get("storage"), sweeper.get("study_name")
    ok = storage and name and "optuna" in str(sweeper.get("_target_", ""))
    return {"storage": storage, "study_name": name} if ok else None


def fail_running_trials(storage: str, study_name: str) -> None:
    """A signal in a trial of a stored Optuna study: the study's running trial (the sweeper runs one at a time)
    is marked failed now, so the stored study never shows it running. Called by the job that the signal stopped
    and again by the command as it exits (`__main__.cli`, with the study `announce_study` returned, in its Lifecycle),
    where nothing the job was doing can stop it."""
    import optuna

    mark_running_failed(optuna.load_study(study_name=study_name, storage=storage))


def mark_running_failed(study) -> int:
    """Marks the study's RUNNING trials failed; returns how many there were."""
    import optuna

    running = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,))
    for trial in running:
        study.tell(trial.number, state=optuna.trial.TrialState.FAIL)
    return len(running)


def run_seeds(cfg, run_dir: Path, life) -> float:
    """trial_seeds=[6,7,8]: train each seed in turn into run_dir/seed<k>/ (an ordinary run dir each) and
    return the mean of their objectives; trial.json holds the per-seed figures as they come. A seed below
    trial_prune_below ends the trial there (trial.json: "pruned": true)."""
    import copy
    import statistics

    from ppo_torchrl.run import rundir
    from ppo_torchrl.trainer import train

    life.commit(run_dir)  # the trial's dir is the seed runs' parent: a seed stopped midway keeps its files
    seeds, values = list(cfg.trial_seeds), []
    for seed in seeds:
        seed_cfg = copy.deepcopy(cfg)
        seed_cfg.seed, seed_cfg.trial_seeds, seed_cfg.trial_prune_below = seed, [], None
        seed_dir = run_dir / f"seed{seed}"
        life.claim(seed_dir)
        try:
            values.append(objective(train(seed_cfg, seed_dir, None, next_steps=False, life=life)))
        finally:
            life.rollback(seed_dir)
        mean = statistics.fmean(values)
        pruned = cfg.trial_prune_below is not None and values[-1] < cfg.trial_prune_below and seed != seeds[-1]
        if not (run_dir / "trial.json").exists():  # listed before it is written (rundir.intend: write-ahead)
            rundir.intend(run_dir, [run_dir / "trial.json"])
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


def announce_study(hydra_cfg, overrides: list[str]) -> dict:
    """`-m hparams_search=...`: say, before it starts, whether the Optuna study is new or resumed. The space
    it searches is the sweeper's params with the command's own overrides over them, as the sweeper reads it.
    Returns the study, {storage, study_name}, for fail_running_trials."""
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
    return {"storage": storage, "study_name": name}


def check_stored_study(study, space: list[str]) -> str:
    """A stored study must search the space the command gives (`key=choice(...)` overrides, the last of a key
    wins; Optuna would fail in the first trial and leave it RUNNING); trials an interrupted sweep left RUNNING
    are marked failed. Returns what it did, for the line."""
    from ppo_torchrl.internals import optuna_space

    wanted = optuna_space(space)
    trials = study.get_trials(deepcopy=False)
    for trial in trials:
        for key, distribution in trial.distributions.items():
            if key in wanted and wanted[key] != distribution:
                raise ConfigError(f"optuna study {study.study_name} searched {key} over {distribution}, this command "
                                  f"over {wanted[key]}; keep the stored space or name a new study with "
                                  "hydra.sweeper.study_name=<name>")
    stale = mark_running_failed(study)
    return f" ({stale} left running by an interrupted sweep marked failed)" if stale else ""


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
