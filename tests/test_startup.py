"""The start-up line (frame budget, what env files and presets change) and resume ergonomics."""

import time

import pytest

from ppo_torchrl.run import checkpoint
from ppo_torchrl.run.lifecycle import resume_config
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.startup import describe_start
from ppo_torchrl.trainer import Trainer

from conftest import compose_config


def start_line(*overrides):
    return describe_start(compose_config(list(overrides)), list(overrides))


def test_start_line_says_the_frame_budget_is_rounded_up():
    line = start_line("experiment=aidl_anymal", "collector.total_frames=8192")
    assert "2 batches x 6400 = 12,800 frames (collector.total_frames=8192 rounded up)" in line
    assert "loss.epochs=48" in line and "collector.total_frames" not in line.split(";", 1)[1]


def test_start_line_names_what_the_env_file_changes_but_not_the_command_line():
    line = start_line("env=HalfCheetah-v4", "policy.width=64", "optim.lr=0.001", "loss=a2c")
    assert line.startswith("start: HalfCheetah-v4, 1954 batches x 512 = 1,000,448 frames")
    changed = line.split("; set by the env file/preset: ", 1)[1].split(", ")
    assert "loss.epochs=20" in changed and "policy.activation=relu" in changed
    assert not [c for c in changed if c.startswith(("policy.width", "optim.lr", "loss.name", "env.", "seed"))]


def test_start_line_of_an_exact_budget_and_the_defaults():
    line = start_line("env=InvertedPendulum-v4", "collector.total_frames=4096")
    assert line == ("start: InvertedPendulum-v4, 2 batches x 2048 = 4,096 frames; collector: FastCollector "
                    "(no env.transforms.extra); the env file/preset changes no defaults")


SAVED = {"config": {"env": {"id": "InvertedPendulum-v4"}}}  # what a checkpoint holds of its config


def saved_run(tmp_path):
    (tmp_path / ".hydra").mkdir()
    (tmp_path / ".hydra" / "hydra.yaml").write_text(
        "hydra:\n  runtime:\n    choices:\n      experiment: null\n      logger: csv\n      env: InvertedPendulum-v4\n")
    return tmp_path


def test_resume_accepts_the_runs_own_group_choices(tmp_path):
    cfg = resume_config(saved_run(tmp_path), ["logger=csv", "env=InvertedPendulum-v4", "collector.total_frames=99"], SAVED)
    assert cfg.collector.total_frames == 99 and cfg.logger.name == "csv"


@pytest.mark.parametrize("override, saved", [("logger=none", "logger=csv"), ("experiment=aidl_anymal", "experiment=null")])
def test_resume_refuses_another_group_choice_naming_the_saved_one(tmp_path, override, saved):
    with pytest.raises(ConfigError, match=f"resume: {override} differs from the run's {saved}"):
        resume_config(saved_run(tmp_path), [override], SAVED)


def test_resumed_run_says_where_it_resumes_and_its_time_goes_on(tiny_cfg, tmp_path, capsys):
    first = Trainer(tiny_cfg("collector.total_frames=512"), tmp_path)
    collect = first.collector.collect
    first.collector.collect = lambda: (time.sleep(0.5), collect())[1]  # the first part takes >= 1 s
    first.train()
    assert capsys.readouterr().err.startswith("start: InvertedPendulum-v4, 2 batches x 256 = 512 frames;")
    state = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    assert state["wall_time"] >= 1.0

    cfg = resume_config(tmp_path, ["collector.total_frames=1000"], state)
    summary = Trainer(cfg, tmp_path, resume=state).train()
    assert capsys.readouterr().err.splitlines()[0] == f"resumed {tmp_path} at frame 512 of 1,024"
    times = [float(row.split(",")[2]) for row in (tmp_path / "metrics.csv").read_text().splitlines()[1:]]
    assert len(times) == 4 and times == sorted(times) and times[2] > state["wall_time"]
    assert summary["wall_s"] >= times[-1]


def test_start_line_leaves_out_what_the_chosen_loss_does_not_read():
    assert "loss.clip_epsilon=0.1" in start_line("env=Hopper-v4")  # Hopper-v4's file sets it for clip_ppo
    line = start_line("env=Hopper-v4", "loss=kl_ppo")
    assert "clip_epsilon" not in line and "policy.width=128" in line


SUMMARY = {"env": "Hopper-v4", "frames": 1_001_472, "wall_s": 3725.0, "eval_return_mean": 3301.26,
           "eval_return_std": 12.04, "best_eval_return": 3350.0, "train_return_last100": 3000.0,
           "run_dir": "/data/runs/my run"}


def test_end_lines_say_what_the_run_reached_and_what_to_paste_next():
    import shlex
    import sys
    from pathlib import Path

    from ppo_torchrl.run.startup import describe_end

    lines = describe_end(SUMMARY).splitlines()
    assert lines[0] == ("done: Hopper-v4, 1,001,472 frames in 1 h 02 min; final eval 3301.3 +- 12.0, best 3350.0; "
                        "files in /data/runs/my run")
    assert len(lines) == 5 and lines[1].startswith("next: ")
    commands = [shlex.split(line) for line in lines[2:]]
    assert all(Path(command[0]).absolute() == Path(sys.executable).absolute() for command in commands)  # this Python
    assert [c[1:] for c in commands] == [
        ["-m", "ppo_torchrl.evaluate", "run=/data/runs/my run", "video=true"],
        ["-m", "ppo_torchrl.report", "/data/runs/my run"],
        ["-m", "ppo_torchrl", "resume=/data/runs/my run", "collector.total_frames=2002944"]]
    # a sweep's job: the line only (the sweep ends with its report command); no eval: the training return
    line = describe_end({**SUMMARY, "eval_return_mean": None, "wall_s": 75.4}, next_steps=False)
    assert line == ("done: Hopper-v4, 1,001,472 frames in 1 min 15 s; no eval; train return (last 100 episodes) "
                    "3000.0; files in /data/runs/my run")


def test_mujocos_deprecation_warning_about_gymnasiums_model_is_not_printed(tmp_path, monkeypatch, capfd):
    import gymnasium as gym

    from ppo_torchrl.run.loggers import quiet_mujoco

    monkeypatch.chdir(tmp_path)
    quiet_mujoco()
    gym.make("HalfCheetah-v4").close()  # its model sets settotalmass
    assert "settotalmass" not in capfd.readouterr().err
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
