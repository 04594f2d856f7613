"""Multirun, Optuna, launcher configs, experiment presets and the sweep report."""

import json
import os
import pickle

import cloudpickle
import pytest
from omegaconf import OmegaConf

from ppo_torchrl import report
from ppo_torchrl.trainer import Trainer
from ppo_torchrl.validation import validate_config

from conftest import ROOT, TINY, App, compose_config, run_cli

PRESETS = ["arena_hopper", "practical_rl_halfcheetah", "reinforce_pendulum", "aidl_halfcheetah", "aidl_anymal",
           "aidl_anymal_step"]


def test_joblib_multirun_runs_every_seed_in_parallel_and_the_report_summarizes_them(tmp_path):
    result = run_cli("-m", "env=InvertedPendulum-v4", "seed=1,2,3", "hydra/launcher=joblib",
                     "hydra.launcher.n_jobs=2", *TINY, f"hydra.sweep.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    runs = sorted(tmp_path.glob("*/summary.json"))
    assert [json.loads(p.read_text())["seed"] for p in runs] == [1, 2, 3]

    # a partial run beside them is left out, with a line saying so
    partial = tmp_path / "9_partial"
    (partial / ".hydra").mkdir(parents=True)
    (partial / "summary.json").write_text(json.dumps({"status": "interrupted", "frames": 256}))
    png, md, csv = report.main([str(tmp_path)])
    assert png.read_bytes()[:4] == b"\x89PNG"
    table = md.read_text()
    assert "| 1 2 3 | 512 |" in table and "skipped 9_partial: status interrupted" in table
    assert csv.read_text().splitlines()[1].split(",")[1] == "1 2 3"
    import numpy as np

    finals = [json.loads((run / "summary.json").read_text())["train_return_last100"]
              for run in sorted(tmp_path.glob("[0-9]_*")) if run.name != "9_partial"]
    row = next(r for r in csv.read_text().splitlines()[1:] if r.split(",")[1] == "1 2 3").split(",")
    assert float(row[5]) == pytest.approx(np.std(finals, ddof=1))  # +- is the sample std over seeds


def test_optuna_search_runs_trials_and_prints_the_best(tmp_path, capsys):
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    args = ["hparams_search=optuna", "env=InvertedPendulum-v4", "hydra.sweeper.n_trials=2", *TINY,
            f"hydra.sweeper.storage={storage}"]
    space = ["optim.lr=choice(1e-4,3e-4)"]  # the command's own space, not the search file's interval
    result = run_cli("-m", *args, *space, f"hydra.sweep.dir={tmp_path / 'sweep'}")
    assert result.returncode == 0, result.stderr[-2000:]
    name = "optuna_InvertedPendulum-v4_512frames"  # the search file, the env, the frame budget
    assert result.stderr.splitlines()[0] == f"optuna: new study {name} in {storage}"
    out = result.stdout + result.stderr
    assert "Best parameters" in out and "Best value" in out
    assert len(list((tmp_path / "sweep").glob("*/summary.json"))) == 2
    import optuna

    study = optuna.load_study(study_name=name, storage=storage)
    assert len(study.trials) == 2  # stored: running the command again resumes this study, and says so
    from ppo_torchrl.sweeps import announce_study

    announce_study(compose_config(args, return_hydra_config=True), args + space)  # the same command: resumed
    assert capsys.readouterr().err == f"optuna: resuming study {name} with 2 trials in {storage}\n"
    assert {t.params["optim.lr"] for t in study.trials} <= {1e-4, 3e-4}


def test_a_multi_seed_study_trains_each_tuning_seed_and_maximizes_their_mean(tmp_path):
    storage = f"sqlite:///{tmp_path / 'study.db'}"
    result = run_cli("-m", "hparams_search=optuna_seeds", "env=InvertedPendulum-v4", "trial_seeds=[6,7]",
                     "hydra.sweeper.n_trials=1", "hydra.sweeper.n_jobs=1", *TINY, f"hydra.sweeper.storage={storage}",
                     f"hydra.sweep.dir={tmp_path / 'sweep'}")
    assert result.returncode == 0, result.stderr[-2000:]
    (trial,) = (tmp_path / "sweep").glob("*/trial.json")
    seeds = [json.loads((trial.parent / f"seed{k}" / "summary.json").read_text()) for k in (6, 7)]
    assert [s["seed"] for s in seeds] == [6, 7] and all(s["status"] == "finished" for s in seeds)
    record = json.loads(trial.read_text())
    from ppo_torchrl.sweeps import objective

    assert record["objective"] == [objective(s) for s in seeds]  # the final eval here (TINY), else the last 100
    import optuna

    (study,) = optuna.get_all_study_summaries(storage)
    value = optuna.load_study(study_name=study.study_name, storage=storage).trials[0].value
    assert value == pytest.approx(sum(record["objective"]) / 2) == record["mean"]
    assert "sweep: 2 of 2 runs finished" in result.stderr
    png, md, _ = report.main([str(trial.parent)])  # the trial's curve: its seeds as one group
    assert png.read_bytes()[:4] == b"\x89PNG" and "| 6 7 |" in md.read_text()


def test_a_trial_stops_at_a_seed_below_trial_prune_below(tmp_path):
    run = tmp_path / "trial"
    result = run_cli("env=InvertedPendulum-v4", "trial_seeds=[6,7]", "trial_prune_below=1e9", *TINY,
                     f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-2000:]
    record = json.loads((run / "trial.json").read_text())
    assert record["seeds"] == [6] and record["pruned"] and not (run / "seed7").exists()
    assert record["mean"] == record["objective"][0] < 1e9
    assert f"trial: seeds 6: {record['mean']:.1f}; mean {record['mean']:.1f} (pruned: seed 6 below 1e+09)" in result.stderr


def test_optuna_study_name_holds_what_defines_the_search():
    def sweeper(*overrides):
        cfg = compose_config(["env=InvertedPendulum-v4", *overrides], return_hydra_config=True)
        return cfg.hydra.sweeper.study_name, cfg.hydra.sweeper.storage, cfg.hydra.sweep.dir

    name, storage, sweep_dir = sweeper("hparams_search=optuna", "collector.total_frames=512")
    assert name == "optuna_InvertedPendulum-v4_512frames"
    assert sweeper("hparams_search=optuna", "collector.total_frames=1024")[0] == "optuna_InvertedPendulum-v4_1024frames"
    assert sweeper("hparams_search=optuna_levers", "collector.total_frames=512")[0] == \
        "optuna_levers_InvertedPendulum-v4_512frames"
    assert sweeper("hparams_search=optuna", "collector.total_frames=512", "hparams_search_name=smoke")[0] == \
        "optuna_InvertedPendulum-v4_512frames_smoke"
    # one folder per study: the sqlite file beside the sweep dir of each command that adds trials
    assert storage == f"sqlite:///outputs/multirun/{name}/optuna.db"
    assert sweep_dir.startswith(f"outputs/multirun/{name}/20")


@pytest.mark.parametrize("launcher", ["joblib", "submitit_slurm", "submitit_local", "ray"])
def test_launcher_configs_compose(launcher):
    if launcher == "ray":
        pytest.importorskip("hydra_plugins.hydra_ray_launcher", reason="the [ray] extra is not installed")
    cfg = compose_config([f"hydra/launcher={launcher}"], return_hydra_config=True)
    assert "Launcher" in cfg.hydra.launcher._target_


def test_multirun_dry_run_shows_the_launcher_the_jobs_and_the_first_jobs_config(tmp_path):
    # Hydra alone refuses -m with --cfg ("Only one of --run, --multirun, --cfg, --info ... can be specified")
    args = ["-m", "seed=1,2", "env=Hopper-v4,Walker2d-v4", "hydra/launcher=submitit_slurm",
            "hydra.launcher.partition=gpu"]
    result = run_cli(*args, "--cfg", "hydra", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    lines = result.stdout.splitlines()
    assert lines[0].startswith("# dry run of -m: launcher hydra_plugins.hydra_submitit_launcher.submitit_launcher."
                               "SlurmLauncher, sweep dir outputs/multirun/")
    assert lines[1:7] == ["# 4 jobs:", "#   #0 : seed=1 env=Hopper-v4", "#   #1 : seed=1 env=Walker2d-v4",
                          "#   #2 : seed=2 env=Hopper-v4", "#   #3 : seed=2 env=Walker2d-v4", "# job #0:"]
    hydra_cfg = OmegaConf.create(result.stdout).hydra  # the lines above are YAML comments
    assert hydra_cfg.launcher.partition == "gpu" and hydra_cfg.mode == "MULTIRUN"
    assert hydra_cfg.overrides.task == ["seed=1", "env=Hopper-v4"]

    job = run_cli(*args, "--cfg", "job", cwd=tmp_path)
    assert job.returncode == 0, job.stderr[-2000:]
    cfg = OmegaConf.create(job.stdout)
    assert (cfg.seed, cfg.env.id) == (1, "Hopper-v4")
    assert list(tmp_path.iterdir()) == []  # nothing ran, nothing was written


def test_the_job_function_pickles():
    from ppo_torchrl.__main__ import main

    clone = pickle.loads(cloudpickle.dumps(main))  # what submitit and ray ship to the workers
    assert clone.__name__ == main.__name__


@pytest.mark.parametrize("preset", PRESETS)
def test_experiment_presets_compose_and_train(preset, tmp_path):
    cfg = compose_config([f"experiment={preset}"])
    validate_config(cfg)
    short = compose_config([f"experiment={preset}", "collector.total_frames=1280", "collector.frames_per_batch=640",
                            "loss.epochs=1", "eval.every_frames=0", "eval.final_episodes=1", "eval.video=false",
                            "logger=none", "loss.minibatch_size=128" if preset != "reinforce_pendulum" else "seed=5"])
    assert Trainer(short, tmp_path).train()["frames"] == 1280


def test_presets_carry_their_documents_settings():
    practical = compose_config(["experiment=practical_rl_halfcheetah"])
    assert (practical.env.id, practical.loss.clip_value, practical.loss.critic_coef) == ("HalfCheetah-v4", 0.2, 0.25)
    reinforce = compose_config(["experiment=reinforce_pendulum"])
    assert (reinforce.loss.name, reinforce.advantage.name, reinforce.policy.std) == ("reinforce", "mc", "state_dependent")
    assert list(reinforce.policy.hidden_sizes) == [16, 32] and reinforce.optim.lr == 1e-4
    aidl = compose_config(["experiment=aidl_halfcheetah"])
    assert aidl.policy.shared_trunk and list(aidl.policy.hidden_sizes) == [64, 128] and aidl.policy.std_min == 0.25
    arena = compose_config(["experiment=arena_hopper"])
    assert arena.env.id == "Hopper-v4" and arena.eval.video
    anymal = compose_config(["experiment=aidl_anymal"])
    assert (anymal.env.xml_file, anymal.policy.std_min, anymal.optim.lr, anymal.loss.clip_epsilon) == \
        ("quadruped.xml", 0.6, 1e-5, 0.1)
    assert (anymal.loss.epochs, anymal.collector.frames_per_batch, anymal.loss.minibatch_size) == (48, 6400, 128)
    assert (anymal.loss.critic_coef, anymal.loss.entropy_coef, anymal.env.max_episode_steps) == (1.0, 0.001, 400)
    step = compose_config(["experiment=aidl_anymal_step"])
    assert step.env.xml_file == "quadruped_step.xml" and step.init_from_optimizer and step.optim.lr == 1e-5


def test_the_halfcheetah_study_preset_is_the_env_file_with_its_best_trials_values():
    """experiment=halfcheetah_study (issue 33's pre-registered row on seeds 16-20) is HalfCheetah-v4's env file with
    Optuna trial 1's eight values and nothing else."""
    env_file = compose_config(["env=HalfCheetah-v4"])
    preset = compose_config(["experiment=halfcheetah_study"])
    trial = {"optim.lr": 5e-5, "advantage.gamma": 0.99, "advantage.lmbda": 0.92, "policy.log_std_init": -1.0,
             "policy.width": 128, "loss.clip_epsilon": 0.2, "loss.epochs": 10, "loss.entropy_coef": 0.002}
    assert {key: OmegaConf.select(preset, key) for key in trial} == trial
    for key, value in trial.items():
        OmegaConf.update(env_file, key, value)
    assert env_file == preset


def test_a_stored_study_with_another_space_is_refused_and_stale_trials_are_failed():
    """hparams_search on a stored study: another search space is one line (Optuna would fail in the first trial
    and leave it RUNNING); trials an interrupted sweep left RUNNING are marked failed."""
    import optuna

    from ppo_torchrl.sweeps import check_stored_study
    from ppo_torchrl.errors import ConfigError

    study = optuna.create_study(direction="maximize")
    study.ask({"optim.lr": optuna.distributions.LogUniformDistribution(1e-5, 3e-3)})  # left RUNNING
    with pytest.raises(ConfigError, match="searched optim.lr over LogUniformDistribution"):
        check_stored_study(study, ["optim.lr=tag(log, interval(1e-4, 1e-2))", "env=Hopper-v4"])
    with pytest.raises(ConfigError, match="searched optim.lr over LogUniformDistribution"):  # the command's own wins
        check_stored_study(study, ["optim.lr=tag(log, interval(1e-5, 3e-3))", "optim.lr=choice(1e-4,3e-4)"])
    assert study.trials[0].state == optuna.trial.TrialState.RUNNING  # a refused command changed nothing
    stored_then_command = ["optim.lr=choice(1e-4,3e-4)", "optim.lr=tag(log, interval(1e-5, 3e-3))", "env=Hopper-v4"]
    assert check_stored_study(study, stored_then_command).startswith(" (1 left running")
    assert [t.state for t in study.trials] == [optuna.trial.TrialState.FAIL]


def test_a_search_space_is_checked_value_by_value_and_a_grid_job_by_job(tmp_path, monkeypatch):
    from ppo_torchrl import __main__ as cli
    from ppo_torchrl.errors import ConfigError

    composed = []
    compose = cli.compose
    monkeypatch.setattr(cli, "compose", lambda job, **kw: composed.append(job) or compose(job, **kw))
    space = ["optim.lr=choice(1e-4,2e-4,3e-4)", "loss.epochs=choice(1,2,3)", "policy.width=choice(16,32,64)"]
    with pytest.raises(SystemExit):
        cli.prepare(["-m", "hparams_search=optuna", "env=InvertedPendulum-v4", *space, "--cfg", "job"])
    checked = [job for job in composed if any(o.startswith("optim.lr=") for o in job)]
    values = {o for job in checked for o in job if o.startswith(("optim.lr=", "loss.epochs=", "policy.width="))}
    assert len(values) == 9 and len(checked) < 12  # every value, not the 27 combinations a sampler draws from
    composed.clear()
    with pytest.raises(SystemExit):
        cli.prepare(["-m", "env=InvertedPendulum-v4", *space, "--cfg", "job"])  # a grid runs them all
    assert len({tuple(job) for job in composed if any(o.startswith("optim.lr=") for o in job)}) == 27
    with pytest.raises(ConfigError, match="loss.minibatch_size=3000"):  # a bad value in the space's tail
        cli.prepare(["-m", "hparams_search=optuna", "env=InvertedPendulum-v4", *space,
                     "loss.minibatch_size=choice(64,3000)", f"hydra.sweep.dir={tmp_path / 'sweep'}"])
    assert not (tmp_path / "sweep").exists()


def test_ctrl_c_in_a_stored_optuna_trial_marks_it_failed(tmp_path):
    """Issue 47: the trial a signal stops is FAIL in the stored study at once, never left RUNNING."""
    import signal
    import subprocess
    import sys
    import time

    import optuna

    storage = f"sqlite:///{tmp_path / 'study.db'}"
    sweep = tmp_path / "sweep"
    args = ["-m", "hparams_search=optuna", "env=InvertedPendulum-v4", "hydra.sweeper.n_trials=2",
            "collector.frames_per_batch=256", "collector.total_frames=1000000", "eval.every_frames=0", "logger=none",
            "compile=false", "optim.lr=choice(1e-4,3e-4)", f"hydra.sweeper.storage={storage}",
            f"hydra.sweep.dir={sweep}"]
    proc = App(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=dict(os.environ))
    try:
        deadline = time.time() + 240
        while time.time() < deadline and not list(sweep.glob("*/metrics.csv")) and proc.poll() is None:
            time.sleep(0.2)
        assert list(sweep.glob("*/metrics.csv")), "the first trial did not start within 240 s"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-1500:]
    (summary,) = optuna.get_all_study_summaries(storage)
    states = [t.state for t in optuna.load_study(study_name=summary.study_name, storage=storage).trials]
    assert states == [optuna.trial.TrialState.FAIL], (states, err[-1500:])
