"""`python -m ppo_torchrl env=Hopper-v4 [overrides]`: train PPO, or sweep with `-m`.

`resume=<run dir> [collector.total_frames=N]` continues a run in its own directory. Returns the
final deterministic eval return (falling back to the last-100 training return), the value a Hydra
sweeper such as Optuna maximizes.

Before Hydra starts (and writes its `.hydra/` files), the command is checked whole: the config is
composed and every value validated (each job of a sweep too), and the run or sweep dir is claimed
(rundir.py). A refused command exits 2 with one line and leaves every file as it was.
"""

from __future__ import annotations

import sys
from pathlib import Path

from ppo_torchrl import signals
from ppo_torchrl.errors import EXIT_SIGNAL, guarded, signal_in_chain
from ppo_torchrl.compose import CONF_DIR, compose, hydra_value, register_resolvers, show_job
from ppo_torchrl.overrides import (HELP_FLAGS, INFO_FLAGS, check_env_override, check_values, route_paths,
                                   split_args, unquote, whole_counts, with_override)
from ppo_torchrl.resume import check_resume
from ppo_torchrl.sweeps import (SWEEP, announce_study, dry_run, fail_running_trials, hydra_overrides, job_dirs,
                                objective, run_seeds, stored_study, sweep_done, sweep_jobs)

if __name__ == "__main__":
    signals.install()  # from here on a Ctrl-C or SIGTERM is one line and exit 130 / 143, imports included

def main(cfg) -> float:
    """The Hydra task function: one training run in its (already claimed) run dir, or with `trial_seeds`
    one run per seed in its seed<k>/ folder, whose objectives are averaged."""
    return guarded(_run_job, cfg)


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
            return run_seeds(cfg, run_dir)
        return objective(train(cfg, run_dir, state, next_steps=not multirun))  # a sweep ends with its report command
    except BaseException as error:  # a signal, also one a library wrapped in its own error (at set-up)
        study = stored_study(HydraConfig.get().sweeper) if multirun else None
        if study and signal_in_chain(error) is not None:
            fail_running_trials(**study)
        raise
    finally:
        rundir.rollback(run_dir)  # a job refused before it started training leaves its dir as it was


def prepare(argv: list[str]) -> list[str]:
    """Check the whole command and claim its dir; returns the argv Hydra runs with."""
    from ppo_torchrl import rundir
    from ppo_torchrl.validation import validate_config

    flags, overrides = split_args(argv)
    if any(f in HELP_FLAGS for f in flags):
        return argv
    check_values(overrides)  # resume= with an empty value, ~seed: one line, before anything else
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
    except BaseException as error:  # a job ends by sys.exit(its code); a signal: 130 / 143
        signalled = signal_in_chain(error) is not None or getattr(error, "code", None) in EXIT_SIGNAL.values()
        if signalled and "study" in SWEEP:
            try:  # the exit keeps its code (130 / 143) whatever the storage does
                fail_running_trials(**SWEEP["study"])
            except Exception as storage_error:  # noqa: BLE001 - the next command on the study marks it failed
                print(f"note: the running trial stays RUNNING in {SWEEP['study']['storage']} ({storage_error}); "
                      "the next command on this study marks it failed", file=sys.stderr, flush=True)
        raise
    finally:  # a sweep dir whose every job was refused, or a run stopped before it started: as it was
        rundir.finish()
    if SWEEP:
        print(sweep_done(SWEEP["dir"]), file=sys.stderr, flush=True)


if __name__ == "__main__":
    guarded(cli)
