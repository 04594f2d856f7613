"""Issue 49: the mistakes a user of SB3, rl-zoo or CleanRL makes first, each one line with the fix; counts
written 1e6; the learning-rate schedule of an extended run."""

import pytest

from ppo_torchrl.__main__ import prepare
from ppo_torchrl.compose import compose
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.overrides import whole_counts


@pytest.mark.parametrize("argv, fix", [
    (["env=Hoper-v4"], "did you mean env=Hopper-v4?"),
    (["env=Swimer-v4"], "did you mean env=gym env.id=Swimmer-v4?"),  # no file, but a Gymnasium id is near
    (["env=Swimmer-v4"], "Swimmer-v4 is a Gymnasium id: env=gym env.id=Swimmer-v4"),
    (["colector.total_frames=1000"], "did you mean collector.total_frames?"),
    (["collector.totl_frames=1000"], "did you mean collector.total_frames?"),
    (["env=Hopper-v4", "env.max_episod_steps=5"], "did you mean env.max_episode_steps?"),
    (["--env", "Hopper-v4"], "not --key value; write env=Hopper-v4"),
    (["--total-timesteps=1e6"], "write collector.total_frames=1e6"),
    (["env=Hopper-v4", "--learning-rate", "3e-4"], "write optim.lr=3e-4"),
])
def test_a_mistake_names_its_fix(argv, fix):
    with pytest.raises(ConfigError) as error:
        prepare(argv)
    assert fix in str(error.value) and "\n" not in str(error.value), str(error.value)


def test_counts_written_like_1e6_are_the_ints_they_are():
    argv = ["env=Hopper-v4", "collector.total_frames=1e6", "collector.frames_per_batch=2.048e3", "optim.lr=3e-4",
            "eval.every_frames=1e5,2e5"]
    overrides = list(argv)
    argv, overrides = whole_counts(argv, overrides, compose)
    assert overrides == argv == ["env=Hopper-v4", "collector.total_frames=1000000", "collector.frames_per_batch=2048",
                                 "optim.lr=3e-4", "eval.every_frames=100000,200000"]  # a float stays a float
    cfg = compose(overrides[:4])
    assert cfg.collector.total_frames == 1_000_000 and cfg.optim.lr == 3e-4
    with pytest.raises(ConfigError, match="could not be converted to Integer"):  # not a whole number: Hydra's word
        compose(whole_counts(["collector.total_frames=1.5e0"], ["collector.total_frames=1.5e0"], compose)[1])


def test_extending_a_run_continues_its_lr_schedule(tiny_cfg, tmp_path):
    """resume= with more collector.total_frames: the lr goes on down from the last update's to 0 at the new
    end (before: back up to where a run of the new length would be, 0.5 -> 0.75 x optim.lr here)."""
    import csv

    from ppo_torchrl import checkpoint
    from ppo_torchrl.trainer import Trainer

    cfg = tiny_cfg("collector.total_frames=512", "logger=csv")
    Trainer(cfg, tmp_path).train()
    state = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    longer = tiny_cfg("collector.total_frames=2048", "logger=csv")
    Trainer(longer, tmp_path, resume=state).train()
    with open(tmp_path / "metrics.csv") as f:
        lrs = [float(row["lr"]) / cfg.optim.lr for row in csv.DictReader(f)]
    assert len(lrs) == 8 and lrs[:2] == [1.0, 0.5]
    assert all(b < a for a, b in zip(lrs, lrs[1:])) and lrs[-1] > 0  # down at every update, across the resume
    assert abs(lrs[2] - 0.5 * 6 / 7) < 1e-4 and abs(lrs[-1] - 0.5 / 7) < 1e-4  # 0.5 to 0 over the 7 steps left


def test_the_eta_leaves_the_warm_up_out(capsys, monkeypatch):
    """The first progress line has no ETA (its iteration holds the compile warm-up); later ones use the rate
    of the recent iterations, not the run's mean SPS that the warm-up drags down."""
    from ppo_torchrl import loggers

    clock = iter([60.0, 61.0, 62.0])  # the first iteration ends after 60 s of warm-up, then 1 s per 1000 frames
    monkeypatch.setattr(loggers.time, "perf_counter", lambda: next(clock))
    progress = loggers.Progress(total_frames=100_000, start_frames=0, every_s=0.0, tty=False)
    for frames in (1000, 2000, 3000):
        progress.update({"frames": frames, "sps": frames / 60}, 1000, force=False)
    lines = capsys.readouterr().err.splitlines()  # with the start and done lines
    assert lines[0].endswith("eta after warm-up"), lines
    assert lines[2].endswith("eta   1.6 min"), lines  # 97,000 frames at 1000/s, not at the mean's 50/s
