"""Reliability round 4 (issue 47): overwrite=true deletes nothing. It moves the old run (or sweep, or trial)
aside in one rename, after taking the lock of every run dir inside it; a run dir in use anywhere inside
refuses it; nothing outside the dir is followed."""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, run_cli
from ppo_torchrl.run import rundir
from ppo_torchrl.run.lifecycle import Lifecycle
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


def manifest(run: Path) -> list:
    return json.loads((run / ".ppo_torchrl.json").read_text())["files"]


def test_evaluate_lists_only_what_it_wrote_so_overwrite_never_takes_a_users_file(finished_run, tmp_path, capsys):
    """The issue's case: a user's csv in eval/, then evaluate, then overwrite=true: the csv is not listed, so the
    overwrite is refused in one line naming it, and every byte stays."""
    run = copy_of(finished_run, tmp_path)
    (run / "eval").mkdir(exist_ok=True)
    (run / "eval" / "paper_numbers.csv").write_text("1\n")
    result = run_cli(f"run={run}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 0, result.stderr[-1500:]
    assert "eval/eval.json" in manifest(run) and "eval/paper_numbers.csv" not in manifest(run)
    before = tree_digest(tmp_path)
    code, lines = refused([*RUN, "overwrite=true", f"hydra.run.dir={run}"], capsys)
    assert code == 2 and len(lines) == 1 and "eval/paper_numbers.csv" in lines[0], lines
    assert tree_digest(tmp_path) == before


@pytest.mark.parametrize("command, target", [
    (["episodes=1"], "eval/eval.json"),
    ([], "policy.pt"),
    ([], "report.png"),
])
def test_evaluate_export_and_report_never_replace_a_file_the_app_did_not_write(finished_run, tmp_path, command,
                                                                                target):
    run = copy_of(finished_run, tmp_path)
    listed_before = [f for f in manifest(run) if f != target]
    (run / ".ppo_torchrl.json").write_text(json.dumps({"app": "ppo_torchrl", "files": listed_before}))
    (run / target).parent.mkdir(exist_ok=True)
    (run / target).write_text("the user's")
    before = tree_digest(tmp_path)
    module = {"policy.pt": "ppo_torchrl.export", "report.png": "ppo_torchrl.report"}.get(target, "ppo_torchrl.evaluate")
    args = [str(run)] if target == "report.png" else [f"run={run}", *command]
    result = run_cli(*args, module=module)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and "is not a file this app wrote" in lines[0], result.stderr
    assert tree_digest(tmp_path) == before


def test_evaluate_never_writes_through_a_symlinked_eval_dir(finished_run, tmp_path):
    run = copy_of(finished_run, tmp_path)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "eval.json").write_text("the user's")
    (run / "eval").symlink_to(elsewhere)
    result = run_cli(f"run={run}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 2 and "is a symlink" in result.stderr, result.stderr[-1500:]
    assert (elsewhere / "eval.json").read_text() == "the user's"


def test_a_manifest_with_entries_that_are_not_paths_is_read_as_naming_nothing(finished_run, tmp_path):
    """Non-string, absolute and '../' entries name no file of the run: evaluate works and lists what it wrote."""
    run = copy_of(finished_run, tmp_path)
    (tmp_path / "outside.txt").write_text("the user's")
    files = manifest(run) + [3, {"a": 1}, None, "../outside.txt", str(tmp_path / "outside.txt")]
    (run / ".ppo_torchrl.json").write_text(json.dumps({"app": "ppo_torchrl", "files": files}))
    result = run_cli(f"run={run}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 0, result.stderr[-1500:]
    assert all(isinstance(f, str) and not f.startswith(("/", "..")) for f in manifest(run))
    assert (tmp_path / "outside.txt").read_text() == "the user's"


def test_shipped_zoo_folders_are_read_only_to_every_command(tmp_path, capsys):
    """evaluate and export of a zoo policy write under outputs/zoo/<name>/ in the working dir; resume of one is
    refused in one line naming init_from."""
    zoo = rundir.ZOO / "Hopper-v4"
    before = tree_digest(zoo)
    result = run_cli(f"run={zoo}", "episodes=1", module="ppo_torchrl.evaluate", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-1500:]
    assert (tmp_path / "outputs" / "zoo" / "Hopper-v4" / "eval.json").is_file()
    result = run_cli(f"run={zoo}", module="ppo_torchrl.export", cwd=tmp_path)
    assert result.returncode == 0 and (tmp_path / "outputs" / "zoo" / "Hopper-v4" / "policy.pt").is_file()
    code, lines = refused([f"resume={zoo}", "collector.total_frames=2000000"], capsys)
    assert code == 2 and len(lines) == 1 and f"init_from={zoo}" in lines[0], lines
    assert tree_digest(zoo) == before


@pytest.mark.parametrize("content", [bytes(range(256)) * 4, b"a;b;c\n1;2;3\n", b"frames,sps\n512,100\n"])
def test_report_on_a_metrics_csv_that_is_not_the_apps_table_is_one_line(finished_run, tmp_path, content):
    run = copy_of(finished_run, tmp_path)
    (run / "metrics.csv").write_bytes(content)
    result = run_cli(str(run), module="ppo_torchrl.report")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), result.stderr[-1500:]
    assert not (run / "report.png").exists()


def test_an_env_key_the_env_does_not_read_is_refused(capsys):
    code, lines = refused(["env=Hopper-v4", "env.locomotion.gait_period=0.6"], capsys)
    assert code == 2 and len(lines) == 1 and "env.locomotion.gait_period works on MJCF robots" in lines[0], lines


def test_evaluate_does_not_file_another_envs_checkpoint_in_a_run(finished_run, tmp_path):
    """zoo/Hopper-v4's folder with a checkpoint of another env: one line; with out= the result goes there."""
    run = copy_of(finished_run, tmp_path)  # an InvertedPendulum-v4 run
    other = rundir.ZOO / "Hopper-v4" / "checkpoints" / "best.pt"
    before = tree_digest(tmp_path)
    result = run_cli(f"run={run}", f"checkpoint={other}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 2 and "is a Hopper-v4 policy and run=" in result.stderr, result.stderr[-1500:]
    assert tree_digest(tmp_path) == before
    result = run_cli(f"run={run}", f"checkpoint={other}", "episodes=1", f"out={tmp_path / 'elsewhere'}",
                     module="ppo_torchrl.evaluate")
    assert result.returncode == 0 and (tmp_path / "elsewhere" / "eval.json").is_file(), result.stderr[-1500:]


def test_a_trial_stopped_in_its_second_seed_can_be_resumed_or_overwritten(finished_run, tmp_path, capsys):
    """Ctrl-C in seed 7 of trial_seeds=[6,7]: the trial's manifest lists seed 6 only; resume= of the trial names
    the seed to resume, and overwrite=true takes the trial (seed 7's files are its own run's, by its manifest)."""
    trial = tmp_path / "trial"
    trial.mkdir()
    copy_of(finished_run, trial, "seed6")
    (trial / "trial.json").write_text(json.dumps({"seeds": [6], "objective": [1.0], "mean": 1.0}))
    rundir.record(trial)
    seed7 = copy_of(finished_run, trial, "seed7")
    summary = json.loads((seed7 / "summary.json").read_text())
    (seed7 / "summary.json").write_text(json.dumps({**summary, "status": "interrupted"}))
    code, lines = refused([f"resume={trial}"], capsys)
    assert code == 2 and len(lines) == 1 and f"resume={seed7} continues its stopped seed" in lines[0], lines
    assert rundir.foreign_files(trial) == []
    result = run_cli(*RUN, "trial_seeds=[6]", "overwrite=true", f"hydra.run.dir={trial}")
    assert result.returncode == 0, result.stderr[-1500:]
    aside = list(tmp_path.glob("trial.replaced-*"))
    assert len(aside) == 1 and (aside[0] / "seed7" / "checkpoints" / "last.pt").is_file()


def test_a_run_killed_during_start_up_can_be_started_again(tmp_path, capsys):
    """kill -9 after Hydra's first files and before the run's first listing: the dir holds the app's empty manifest
    and .hydra/; a new run there is refused naming overwrite=true, which then takes it (nothing deleted)."""
    run = tmp_path / "run"
    (run / ".hydra").mkdir(parents=True)
    (run / ".ppo_torchrl.json").write_text(json.dumps({"app": "ppo_torchrl", "files": []}))
    for name in ("config", "hydra", "overrides"):
        (run / ".hydra" / f"{name}.yaml").write_text("{}\n")
    code, lines = refused([*RUN, f"hydra.run.dir={run}"], capsys)
    assert code == 2 and len(lines) == 1 and "overwrite=true" in lines[0], lines
    result = run_cli(*RUN, "overwrite=true", f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-1500:]
    assert (next(tmp_path.glob("run.replaced-*")) / ".hydra" / "config.yaml").read_text() == "{}\n"


WAIT_FOREVER = """
import multiprocessing, os, signal, sys, threading, torch
sys.path.insert(0, {tests!r})
from conftest import TINY, compose_config
from ppo_torchrl.collectors import make_collector
from ppo_torchrl.envs.make import env_spec
from ppo_torchrl.errors import EnvironmentFault
from ppo_torchrl.rl.models import make_actor_critic

if __name__ == "__main__":
    cfg = compose_config(["env=InvertedPendulum-v4", *TINY, "collector.workers=2", "collector.num_envs=2"])
    collection = make_collector(cfg, make_actor_critic(cfg.policy, env_spec(cfg.env)), 3, torch.device("cpu"))
    try:
        collection.collect()
        procs = collection.collector.procs
        reader, writer = multiprocessing.Pipe(duplex=False)  # nothing is ever sent: recv() would wait for ever
        threading.Timer(1.0, os.kill, (procs[1].pid, signal.SIGKILL)).start()
        print("killed", procs[1].pid, flush=True)
        reader.recv()
    except EnvironmentFault as error:
        print("raised", error, flush=True)
        procs[0].join()  # ends only if something ended it
        print("other", procs[0].exitcode, flush=True)
    finally:
        collection.close()
"""


def test_a_dead_worker_ends_any_wait_of_the_main_process(tmp_path):
    """Issue 47, item 4: the main process blocked where no timeout would ever fire (a read of a pipe nothing
    writes) is woken by a worker's death itself: the wait is bounded by the death, not by a clock."""
    script = tmp_path / "wait_forever.py"
    script.write_text(WAIT_FOREVER.format(tests=str(ROOT / "tests")))
    process = subprocess.Popen([sys.executable, str(script)], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = process.communicate(timeout=600)  # a safety net for a broken build, not a timing claim
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 0, err[-2000:]
    pid = int(next(line for line in out.splitlines() if line.startswith("killed")).split()[1])
    assert f"raised collector worker 1 (pid {pid}) died (killed by SIGKILL)" in out, out
    assert "other -9" in out  # the other worker is stopped too (SIGKILL): nothing is left to wait for


def test_a_sweep_into_a_run_dir_is_told_it_holds_a_run_not_foreign_files(tmp_path):
    """A `-m` sweep whose hydra.sweep.dir is a run (a trial's, with .hydra/ and seed<k>/ runs) answers by the
    dir's manifest: 'already holds', with overwrite=true to replace it, not 'files this app did not write'."""
    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError

    run = tmp_path / "trial"
    life = Lifecycle()
    life.claim(run)
    rundir.atomic_write_bytes(run / ".hydra" / "config.yaml", lambda f: f.write(b"{}\n"))
    life.commit(run)
    seed = run / "seed1"
    life.claim(seed)
    rundir.atomic_write_bytes(seed / "summary.json", lambda f: f.write(b"{}\n"))
    life.commit(seed)
    life.finish()
    with pytest.raises(ConfigError, match="already holds a sweep.*overwrite=true"):
        rundir.check_new_dir(run, overwrite=False, what="sweep")
    rundir.check_new_dir(run, overwrite=True, what="sweep")  # replaceable


def test_a_sweep_killed_before_it_listed_hydras_multirun_yaml_can_be_overwritten(tmp_path):
    """kill -9 of a `-m` sweep after Hydra wrote multirun.yaml and before the sweep's listing (found by
    benchmarks/data_safety.py --real): the dir is still the app's, and overwrite=true takes it."""
    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError

    sweep = tmp_path / "sweep"
    life = Lifecycle()
    life.claim(sweep, what="sweep")  # its manifest, listing nothing yet
    (sweep / "multirun.yaml").write_text("hydra: {}\n")  # Hydra's, then the kill
    life.release(sweep)
    with pytest.raises(ConfigError, match="already holds a sweep"):
        rundir.check_new_dir(sweep, overwrite=False, what="sweep")
    rundir.check_new_dir(sweep, overwrite=True, what="sweep")
    rundir.check_new_dir(sweep, overwrite=True, what="run")
