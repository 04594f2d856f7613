"""Interruption, resume, determinism, non-finite values and bad input (the reliability issue)."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch

from ppo_torchrl.run import checkpoint
from ppo_torchrl.run.lifecycle import resume_config
from ppo_torchrl.errors import ConfigError, Interrupted, TrainingError
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, App, run_cli

FOUR_ITERATIONS = ["collector.total_frames=1024", "eval.every_frames=512", "eval.episodes=1",
                   "checkpoint.every_frames=0", "logger=csv"]


def metric_rows(run_dir):
    lines = (run_dir / "metrics.csv").read_text().splitlines()
    header = lines[0].split(",")
    skip = {header.index("time_s"), header.index("sps")}  # wall-clock columns
    return [[v for i, v in enumerate(line.split(",")) if i not in skip] for line in lines[1:]]


@pytest.mark.parametrize("backend, envs, background, workers", [
    ("fast", 1, "false", 1), ("torchrl", 1, "false", 1), ("torchrl", 2, "false", 1), ("fast", 1, "true", 1),
    ("torchrl", 1, "false", 2)])  # TorchRL's Collector in worker processes: each worker's torch RNG resumes too
def test_interrupted_and_resumed_run_matches_an_uninterrupted_one(tiny_cfg, tmp_path, backend, envs, background,
                                                                 workers):
    overrides = [*FOUR_ITERATIONS, f"collector.backend={backend}", f"collector.num_envs={envs}",
                 f"collector.workers={workers}",
                 f"eval.background={background}"]  # true: an eval is under way when the signal comes
    Trainer(tiny_cfg(*overrides), tmp_path / "straight").train()

    interrupted = Trainer(tiny_cfg(*overrides), tmp_path / "cut")
    collect = interrupted.collector.collect

    def collect_then_signal():  # SIGINT arrives during the second iteration's collection
        batch = collect()
        if interrupted.iteration == 1:
            os.kill(os.getpid(), signal.SIGINT)
        return batch

    interrupted.collector.collect = collect_then_signal
    with pytest.raises(Interrupted, match="checkpoint at frame 512"):
        interrupted.train()
    assert json.loads((tmp_path / "cut" / "summary.json").read_text())["status"] == "interrupted"

    state = checkpoint.load(tmp_path / "cut" / "checkpoints" / "last.pt")
    assert state["frames"] == 512 and state["iteration"] == 2
    cfg = resume_config(tmp_path / "cut", [], checkpoint.load(tmp_path / "cut" / "checkpoints" / "last.pt"))
    Trainer(cfg, tmp_path / "cut", resume=state).train()

    straight, resumed = metric_rows(tmp_path / "straight"), metric_rows(tmp_path / "cut")
    assert len(resumed) == 4
    assert resumed == straight  # every metric of every iteration, after the resume too
    lr_steps = [l.split(",")[0] for l in (tmp_path / "cut" / "logs/csv/scalars/lr.csv").read_text().splitlines()]
    assert lr_steps == ["256", "512", "768", "1024"]  # the logger's step continues, no duplicates


def test_resume_with_more_frames_and_stale_rows_are_dropped(tiny_cfg, tmp_path):
    Trainer(tiny_cfg("collector.total_frames=512"), tmp_path).train()
    with open(tmp_path / "metrics.csv", "a") as f:  # a row logged after the last checkpoint
        f.write("3,768" + "," * 23 + "\n")
    cfg = resume_config(tmp_path, ["collector.total_frames=1024"], checkpoint.load(tmp_path / "checkpoints" / "last.pt"))
    summary = Trainer(cfg, tmp_path, resume=checkpoint.load(tmp_path / "checkpoints" / "last.pt")).train()
    assert summary["frames"] == 1024
    frames = [int(r.split(",")[1]) for r in (tmp_path / "metrics.csv").read_text().splitlines()[1:]]
    assert frames == [256, 512, 768, 1024]


def test_non_finite_loss_stops_with_a_clear_error_and_keeps_the_good_checkpoint(tiny_cfg, tmp_path):
    trainer = Trainer(tiny_cfg("collector.total_frames=1024", "checkpoint.every_frames=256"), tmp_path)
    loss_step, calls = trainer.minibatch_step.loss_step, {"n": 0}

    def poisoned(minibatch):  # the 3rd minibatch of the 2nd iteration goes non-finite
        loss, out = loss_step(minibatch)
        calls["n"] += 1
        if calls["n"] == 8 + 3:
            loss = loss * float("nan")
        return loss, out

    trainer.minibatch_step.loss_step = poisoned
    with pytest.raises(TrainingError, match=r"non-finite loss at iteration 2 .*epoch 1, minibatch 3"):
        trainer.train()
    state = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    assert state["frames"] == 256  # iteration 1's checkpoint, not overwritten
    assert all(torch.isfinite(v).all() for v in state["actor"].values())
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "failed"


def test_resume_into_an_env_of_other_shapes_is_refused(tiny_cfg, tmp_path):
    Trainer(tiny_cfg(), tmp_path).train()
    cfg = resume_config(tmp_path, ["env.id=Hopper-v4", "collector.total_frames=1024"],
                        checkpoint.load(tmp_path / "checkpoints" / "last.pt"))
    with pytest.raises(ConfigError, match="observations of size 4 .* Hopper-v4 has 11"):
        Trainer(cfg, tmp_path, resume=checkpoint.load(tmp_path / "checkpoints" / "last.pt"))


def test_resume_refuses_group_swaps(tmp_path):
    state = {"config": {"env": {"id": "InvertedPendulum-v4"}}}
    with pytest.raises(ConfigError, match="only key=value overrides"):
        resume_config(tmp_path, ["loss=kl_ppo"], state)


@pytest.mark.parametrize(
    "args, expected",
    [  # end to end, as a user runs it (the full table of bad inputs is in test_bad_input.py, in-process)
        (["loss=trpo"], "Available options in 'loss': a2c, clip_ppo"),
        (["env=InvertedPendulum-v4", "optim.lr=-1"], "optim.lr=-1.0 must be > 0"),
    ],
)
def test_bad_input_is_one_line_and_a_nonzero_exit(tmp_path, args, expected):
    result = run_cli(*args, f"hydra.run.dir={tmp_path / 'run'}")
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    lines = [l for l in result.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0]
    assert not (tmp_path / "run").exists()


def test_corrupt_checkpoint_on_resume_is_one_line(tiny_cfg, tmp_path):
    Trainer(tiny_cfg(), tmp_path).train()
    (tmp_path / "checkpoints" / "last.pt").write_bytes(b"\x00garbage")
    result = run_cli(f"resume={tmp_path}")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "corrupt" in result.stderr.strip().splitlines()[-1]


def test_sigint_to_a_training_process_leaves_a_checkpoint_that_resumes(tmp_path):
    run = tmp_path / "run"
    args = ["env=InvertedPendulum-v4", "collector.total_frames=1000000", "collector.frames_per_batch=512",
            "loss.minibatch_size=128", "eval.every_frames=0", "eval.final_episodes=1",
            "checkpoint.every_frames=0", f"hydra.run.dir={run}"]
    proc = App(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.time() + 120
    while time.time() < deadline:  # wait until a few iterations are done
        summary = run / "summary.json"
        if summary.exists() and json.loads(summary.read_text())["frames"] >= 2048:
            break
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    last_line = err.strip().splitlines()[-1]
    assert last_line.startswith("interrupted: checkpoint at frame") and str(run / "checkpoints" / "last.pt") in last_line

    state = checkpoint.load(run / "checkpoints" / "last.pt")
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["frames"] == state["frames"] >= 2048
    assert np.isfinite(state["normalization"]["obs"]["mean"]).all()

    target = state["frames"] + 1024
    result = run_cli(f"resume={run}", f"collector.total_frames={target}")
    assert result.returncode == 0, result.stderr[-2000:]
    summary = json.loads((run / "summary.json").read_text())
    assert summary["frames"] == target and summary["status"] == "finished"
    frames = [int(r.split(",")[1]) for r in (run / "metrics.csv").read_text().splitlines()[1:]]
    assert frames == list(range(512, target + 1, 512))  # continuous: no gap, no repeat
