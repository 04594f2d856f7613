"""One run lifecycle (lifecycle.py): a command's claims live in its Lifecycle, not in a module; the env the
command's check built is the one the run steps first; a resume reads its checkpoint once."""

from __future__ import annotations

import pytest

from ppo_torchrl.run import checkpoint

from ppo_torchrl.envs import make as envs
from ppo_torchrl.collectors.collection import Collection
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.lifecycle import Lifecycle

TINY = ["env=InvertedPendulum-v4", "collector.total_frames=512", "collector.frames_per_batch=256", "loss.epochs=1",
        "eval.every_frames=0", "eval.final_episodes=1", "eval.video=false", "logger=none", "torch_threads=1"]


@pytest.fixture
def counted(monkeypatch):
    """Gymnasium envs built, and how many there were when the collector took its first batch."""
    built, at_first_batch = [], []
    make, collect = envs.make_gym_env, Collection.collect

    def first_collect(self):
        if not at_first_batch:
            at_first_batch.append(len(built))
        return collect(self)

    monkeypatch.setattr(envs, "make_gym_env", lambda *a, **k: built.append(1) or make(*a, **k))
    monkeypatch.setattr(Collection, "collect", first_collect)
    return built, at_first_batch


def test_a_run_builds_its_env_once_before_step_1(tmp_path, counted):
    import ppo_torchrl

    built, at_first_batch = counted
    ppo_torchrl.train(TINY, run_dir=tmp_path / "run")
    assert at_first_batch == [1]  # the check's env is the one the collector steps: no second build, no cache


def test_a_resume_reads_its_checkpoint_once_and_builds_its_env_once(tmp_path, counted, monkeypatch):
    import ppo_torchrl

    ppo_torchrl.train(TINY, run_dir=tmp_path / "run")
    built, at_first_batch = counted
    built.clear()
    at_first_batch.clear()
    loads, load = [], checkpoint.load
    monkeypatch.setattr(checkpoint, "load", lambda *a, **k: loads.append(a[0]) or load(*a, **k))
    run = ppo_torchrl.train(["collector.total_frames=1024"], resume=tmp_path / "run")
    assert run.summary["frames"] == 1024 and at_first_batch == [1]
    assert [p.name for p in loads].count("last.pt") == 1


def test_two_commands_in_one_process_hold_nothing_of_each_other(tmp_path):
    """Claims are a Lifecycle's: one command's finish gives back its locks and undoes what it claimed, and a
    second command's Lifecycle starts empty (no module keeps a run's facts)."""
    first, second = Lifecycle(), Lifecycle()
    first.new_run(tmp_path / "a")
    with pytest.raises(ConfigError, match="in use by"):  # one process, two commands: the lock is per command
        second.claim(tmp_path / "a")
    first.finish()  # refused before it started: the dir is gone again, its lock let go
    assert not (tmp_path / "a").exists()
    assert second.new_run(tmp_path / "a").run_dir == tmp_path / "a"
    second.commit(tmp_path / "a")
    second.finish()
    assert (tmp_path / "a" / ".ppo_torchrl.json").is_file()  # committed: kept


def test_an_overwritten_sweep_names_its_sibling_before_any_job_runs(tmp_path, capsys):
    """A sweep commits at its end: a kill -9 during a job left the old sweep's sibling unnamed (issue 60's long
    mode). The overwrite names it as it moves it, and a sweep whose jobs never start puts it back."""
    sweep = tmp_path / "sweep"
    life = Lifecycle()
    life.claim(sweep, what="sweep")
    life.claim(sweep / "0", what="job")
    life.commit(sweep / "0")
    life.finish()
    capsys.readouterr()
    life = Lifecycle()
    life.claim(sweep, overwrite=True, what="sweep")
    aside = next(tmp_path.glob("sweep.replaced-*"))
    assert f"the sweep that was in {sweep} is now {aside}" in capsys.readouterr().err  # before any job ran
    life.finish()  # no job started: the old sweep goes back
    assert (sweep / "0" / ".ppo_torchrl.json").is_file() and not aside.exists()
    assert "is now" not in capsys.readouterr().err  # said once
