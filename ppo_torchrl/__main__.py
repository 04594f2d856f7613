"""`python -m ppo_torchrl env=Hopper-v4 [overrides]`: train PPO, or sweep with `-m`.

`resume=<run dir> [collector.total_frames=N]` continues a run in its own directory. Returns the
final deterministic eval return (falling back to the last-100 training return), the value a Hydra
sweeper such as Optuna maximizes.

Before Hydra starts (and writes its `.hydra/` files), the command is checked whole: the config is
composed and every value validated (each job of a sweep too), and the run or sweep dir is claimed
(lifecycle.py). A refused command exits 2 with one line and leaves every file as it was.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Optional

from ppo_torchrl.run import signals
from ppo_torchrl.errors import EXIT_SIGNAL, guarded, signal_in_chain
from ppo_torchrl.compose import compose, hydra_value, register_resolvers, show_job
from ppo_torchrl.conf_files import CONF_DIR
from ppo_torchrl.overrides import (HELP_FLAGS, INFO_FLAGS, checked_overrides, plain_keys, split_args, unquote,
                                   with_override)
from ppo_torchrl.run.lifecycle import Lifecycle, Start
from ppo_torchrl.sweeps import (announce_study, dry_run, fail_running_trials, hydra_overrides, job_dirs, objective,
                                run_seeds, stored_study, sweep_done, sweep_jobs)
from ppo_torchrl.validation import validate_config

if __name__ == "__main__":
    signals.install()  # from here on a Ctrl-C or SIGTERM is one line and exit 130 / 143, imports included

def main(cfg) -> float:
    """The Hydra task function of a sweep's job: one training run in its dir, which it claims, or with
    `trial_seeds` one run per seed in its seed<k>/ folder, whose objectives are averaged. (A launcher may run
    it in another process: the job holds a Lifecycle of its own.)"""
    return guarded(_run_job, cfg, Lifecycle())


def _run_job(cfg, life: Lifecycle) -> float:
    from hydra.core.hydra_config import HydraConfig

    from ppo_torchrl.trainer import train

    multirun = HydraConfig.get().mode.name == "MULTIRUN"
    start = life.start  # a single run's (new or resumed): claimed before Hydra started
    if start is None and cfg.resume:  # -m resume=<dir>,<dir>: each job continues its run
        start = life.resume(cfg.resume, [o for o in HydraConfig.get().overrides.task if not o.startswith("resume=")])
    elif start is None:
        start = Start(Path(HydraConfig.get().runtime.output_dir))
        life.claim(start.run_dir, what="job")
    cfg = start.cfg if start.cfg is not None else cfg
    try:
        if cfg.trial_seeds:
            return run_seeds(cfg, start.run_dir, life)
        summary = train(cfg, start.run_dir, start.state, next_steps=not multirun, spec=life.env_spec(cfg.env),
                        life=life)
        return objective(summary)  # a sweep ends with its report command
    except BaseException as error:  # a signal, also one a library wrapped in its own error (at set-up)
        study = stored_study(HydraConfig.get().sweeper) if multirun else None
        if study and signal_in_chain(error) is not None:
            fail_running_trials(**study)
        raise
    finally:
        life.rollback(start.run_dir)  # a job refused before it started training leaves its dir as it was
        if multirun:
            life.finish()


def prepare(argv: list[str], life: Optional[Lifecycle] = None) -> list[str]:
    """Check the whole command and claim its dir (in `life`, the command's); returns the argv Hydra runs with.
    Without a Lifecycle (a test): the check alone, whatever it claimed given back as it returns."""
    if life is None:
        life = Lifecycle()
        try:
            return prepare(argv, life)
        finally:
            life.finish()
    flags, overrides = split_args(argv)
    if any(f in HELP_FLAGS for f in flags):
        return argv
    resume = next((unquote(o.split("=", 1)[1]) for o in plain_keys(overrides) if o.startswith("resume=")), None)
    # the checks the API runs too: ++key as key, empty paths, ~seed, env=, 1e6 as an int: one line, before anything else
    overrides = checked_overrides(overrides, compose)
    argv = [*flags, *overrides]
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
        run_dir = life.resume(resume, overrides).run_dir
        # Keep the run's own .hydra/ as it was: the saved config is the one that resumes.
        return with_override(argv, "hydra.run.dir", run_dir) + ["hydra.output_subdir=null"]
    checked = []  # the env configs built so far: a sweep's jobs that share one are checked with one env
    for job in jobs:  # every job, before the first one runs
        cfg = compose(job)
        if multirun:
            validate_config(cfg, build_env=not any(cfg.env == env for env in checked))
            checked.append(cfg.env)
        else:
            life.check(cfg, keep_env=True)  # the env it builds is the run's first
    if hydra_cfg is None:  # a single run's (a resume has returned above: it keeps its run's own config)
        hydra_cfg = compose(overrides, with_hydra=True)
    overwrite = bool(hydra_cfg.get("overwrite", False))
    if multirun:
        if any(o.startswith("hparams_search=") for o in overrides):
            life.study = announce_study(hydra_cfg, overrides)
        sweep_dir = life.sweep(Path(hydra_value(hydra_cfg, "hydra.sweep.dir")), overwrite)
        return with_override(argv, "hydra.sweep.dir", sweep_dir) + job_dirs(overrides, basic)
    run_dir = life.new_run(Path(hydra_value(hydra_cfg, "hydra.run.dir")), overwrite).run_dir
    signals.ON_DISK.run_dir = run_dir
    return with_override(argv, "hydra.run.dir", run_dir)


def cli() -> None:
    from ppo_torchrl.cli import check_interpreter

    check_interpreter()  # the system Python of a checkout: one line that names the right one
    import hydra

    from ppo_torchrl.run.loggers import quiet_mujoco

    quiet_mujoco()  # from the first model the command's check compiles

    register_resolvers()
    life = Lifecycle()  # this command's claims, from its check to its end
    try:
        sys.argv = [sys.argv[0]] + prepare(sys.argv[1:], life)

        def run(cfg) -> float:  # a single run: the run prepare() claimed (a sweep's jobs: main, each its own)
            return guarded(_run_job, cfg, life)

        task = main if life.sweep_dir is not None else run
        # Hydra's own errors (a full disk as it writes .hydra/) are raised to the one error line (errors.py), not
        # printed by Hydra as a traceback
        os.environ["HYDRA_FULL_ERROR"] = "1"
        hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")(task)()
    except BaseException as error:  # a job ends by sys.exit(its code); a signal: 130 / 143
        signalled = signal_in_chain(error) is not None or getattr(error, "code", None) in EXIT_SIGNAL.values()
        if signalled and life.study:
            try:  # the exit keeps its code (130 / 143) whatever the storage does
                fail_running_trials(**life.study)
            except Exception as storage_error:  # noqa: BLE001 - the next command on the study marks it failed
                print(f"note: the running trial stays RUNNING in {life.study['storage']} ({storage_error}); "
                      "the next command on this study marks it failed", file=sys.stderr, flush=True)
        raise
    finally:  # a sweep dir whose every job was refused, or a run stopped before it started: as it was
        life.finish()
    if life.sweep_dir is not None:
        print(sweep_done(life.sweep_dir), file=sys.stderr, flush=True)


if __name__ == "__main__":
    try:
        guarded(cli)
    finally:
        signals.ignore_from_now()
