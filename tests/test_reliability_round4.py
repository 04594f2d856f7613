"""Reliability round 4 (issue 47): overwrite=true deletes nothing. It moves the old run (or sweep, or trial)
aside in one rename, after taking the lock of every run dir inside it; a run dir in use anywhere inside
refuses it; nothing outside the dir is followed."""

from __future__ import annotations

import fcntl
import json
import os
from pathlib import Path

import pytest

from conftest import run_cli
from ppo_torchrl import rundir
from test_bad_input import finished_run, refused, tree_digest  # noqa: F401  (the module's finished run)
from test_reliability_round3 import RUN, copy_of


def held(directory: Path) -> int:
    """Another open file description locking `directory`, as a process training there holds it."""
    fd = os.open(directory, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    return fd


def test_a_sweep_overwrite_is_refused_while_one_of_its_jobs_trains(finished_run, tmp_path, capsys):
    sweep = tmp_path / "swc"
    job = copy_of(finished_run, sweep, "0_InvertedPendulum-v4_seed1")
    copy_of(finished_run, sweep, "1_InvertedPendulum-v4_seed2")
    before = tree_digest(tmp_path)
    fd = held(job)  # resume=swc/0 collector.total_frames=400000 &
    try:
        code, lines = refused(["-m", *RUN, "seed=1,2", "overwrite=true", f"hydra.sweep.dir={sweep}"], capsys)
    finally:
        os.close(fd)
    assert code == 2 and len(lines) == 1 and f"{job.resolve()} is in use by pid" in lines[0], lines
    assert tree_digest(tmp_path) == before and sorted(p.name for p in tmp_path.iterdir()) == ["swc"]


def test_a_trial_overwrite_is_refused_while_one_of_its_seeds_trains(finished_run, tmp_path, capsys):
    trial = tmp_path / "trial"
    trial.mkdir()
    seed6 = copy_of(finished_run, trial, "seed6")
    rundir.record(trial)  # the trial's own manifest, as _run_seeds writes it
    before = tree_digest(tmp_path)
    fd = held(seed6)
    try:
        code, lines = refused([*RUN, "trial_seeds=[6,7]", "overwrite=true", f"hydra.run.dir={trial}"], capsys)
    finally:
        os.close(fd)
    assert code == 2 and len(lines) == 1 and "is in use by pid" in lines[0], lines
    assert tree_digest(tmp_path) == before


@pytest.mark.parametrize("damage", ["stash_symlink", "manifest_outside", "stash_file"])
def test_overwrite_follows_nothing_out_of_the_run_and_deletes_nothing(finished_run, tmp_path, damage):
    """A .replaced symlink to the user's folder, manifest entries that point out of the run dir, a file already
    in .replaced/: after overwrite=true every one of those bytes is still there (the old run moved aside whole)."""
    keep = tmp_path / "keep"
    keep.mkdir()
    (keep / "config.yaml").write_text("the user's")
    (tmp_path / "victim.txt").write_text("the user's too")
    run = copy_of(finished_run, tmp_path)
    if damage == "stash_symlink":
        (run / ".replaced").symlink_to(keep)
    elif damage == "manifest_outside":
        manifest = json.loads((run / ".ppo_torchrl.json").read_text())
        manifest["files"] += ["../victim.txt", str(keep / "config.yaml")]
        (run / ".ppo_torchrl.json").write_text(json.dumps(manifest))
    else:
        (run / ".replaced").mkdir()
        (run / ".replaced" / "config.yaml").write_text("an earlier version's, or the user's")
    old = tree_digest(run) if damage != "stash_symlink" else None
    outside = {p: p.read_bytes() for p in (keep / "config.yaml", tmp_path / "victim.txt")}
    result = run_cli(*RUN, "overwrite=true", f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-1500:]
    assert all(p.read_bytes() == data for p, data in outside.items())
    aside = list(tmp_path.glob("run.replaced-*"))
    assert len(aside) == 1 and (aside[0] / "checkpoints" / "last.pt").is_file()
    if old is not None:
        assert tree_digest(aside[0]) == old
    assert json.loads((run / "summary.json").read_text())["status"] == "finished"


def test_resume_of_a_dir_that_overwrite_moved_names_where_the_run_went(finished_run, tmp_path, capsys):
    """A kill -9 between overwrite's rename and the new run's first file leaves the old run whole in the sibling;
    resume= of the now missing dir says which dir to resume."""
    moved = copy_of(finished_run, tmp_path, "run.replaced-20261127-101010")
    code, lines = refused([f"resume={tmp_path / 'run'}"], capsys)
    assert code == 2 and len(lines) == 1 and f"resume={moved}" in lines[0], lines
