"""Reliability round 3: overwrite=true deletes only what the app wrote, resume never invents a config, a
signal in the last iteration or the final eval stops the run, helpers may die, and what a user can fix is
one line. Each refused command leaves every file as it was (digest before and after)."""

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from ppo_torchrl.run import checkpoint

from ppo_torchrl.run import lifecycle

from ppo_torchrl.run import rundir
from ppo_torchrl.errors import Interrupted, exit_code, guarded, message_of
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, TINY, App, run_cli
from test_bad_input import finished_run, refused, tree_digest  # noqa: F401  (the module's finished run)

RUN = ["env=InvertedPendulum-v4", *TINY]


def copy_of(run, tmp_path, name="run"):
    target = tmp_path / name
    shutil.copytree(run, target, symlinks=True)
    return target


def user_files(run):
    """Files the app never wrote, put where an adversary put them."""
    (run / "logs").mkdir(exist_ok=True)
    (run / "logs" / "my_notes.txt").write_text("mine")
    return run


def only_logs(run):
    shutil.rmtree(run)
    (run / "logs").mkdir(parents=True)
    (run / "logs" / "events.txt").write_text("mine")
    return run


def only_policy(run):
    shutil.rmtree(run)
    run.mkdir()
    (run / "policy.pt").write_bytes(b"mine")
    return run


def linked_checkpoints(run):
    shutil.move(run / "checkpoints", run.parent / "elsewhere")
    (run / "checkpoints").symlink_to(run.parent / "elsewhere")
    return run


def eval_csv(run):
    (run / "eval").mkdir()
    (run / "eval" / "paper_numbers.csv").write_text("1,2\n")
    return run


def legacy(run):
    (run / rundir.MANIFEST).unlink()  # a run of an earlier version: no list of its files
    return run


@pytest.mark.parametrize("damage, expected", [
    (legacy, "holds a run of an earlier version"),
    (user_files, "it holds logs/my_notes.txt, which this app did not write"),
    (eval_csv, "it holds eval/paper_numbers.csv"),
    (only_logs, "is not a ppo_torchrl run dir"),
    (only_policy, "it holds policy.pt"),
    (linked_checkpoints, "holds a symlink"),
])
@pytest.mark.parametrize("overwrite", [True, False])
def test_overwrite_never_deletes_what_the_app_did_not_write(finished_run, tmp_path, capsys, damage, expected, overwrite):
    run = damage(copy_of(finished_run, tmp_path))
    before = tree_digest(tmp_path)
    code, lines = refused([*RUN, f"hydra.run.dir={run}", *(["overwrite=true"] if overwrite else [])], capsys)
    assert code == 2 and len(lines) == 1 and expected in lines[0], lines
    assert tree_digest(tmp_path) == before


def test_a_sweep_with_a_user_folder_or_file_is_refused_whole(finished_run, tmp_path, capsys):
    sweep = tmp_path / "sweep"
    copy_of(finished_run, sweep, "0_InvertedPendulum-v4_seed1")
    (sweep / "mydata" / "checkpoints").mkdir(parents=True)
    (sweep / "mydata" / "checkpoints" / "a.pt").write_bytes(b"mine")
    (sweep / "0_InvertedPendulum-v4_seed1" / "notes.txt").write_text("mine")
    before = tree_digest(sweep)
    code, lines = refused(["-m", *RUN, "seed=1,2", "overwrite=true", f"hydra.sweep.dir={sweep}"], capsys)
    assert code == 2 and "mydata/checkpoints/a.pt" in lines[0] and "notes.txt" in lines[0]
    assert tree_digest(sweep) == before


def test_overwrite_with_a_rejected_init_from_keeps_the_old_run(finished_run, tmp_path):
    run = copy_of(finished_run, tmp_path)
    before = tree_digest(run)
    result = run_cli(*RUN, "overwrite=true", f"init_from={run}", "policy.width=32", f"hydra.run.dir={run}")
    assert result.returncode == 2 and "networks do not fit" in result.stderr, result.stderr[-1000:]
    assert result.stderr.strip().count("\n") == 0 and tree_digest(run) == before
    fresh = tmp_path / "new" / "run"  # a rejected init_from into a new dir leaves no dir behind
    result = run_cli(*RUN, f"init_from={run}", "policy.width=32", f"hydra.run.dir={fresh}")
    assert result.returncode == 2 and not (tmp_path / "new").exists()


def test_overwrite_may_start_from_the_run_it_replaces(finished_run, tmp_path):
    run = copy_of(finished_run, tmp_path)
    old = tree_digest(run)
    result = run_cli(*RUN, "overwrite=true", f"init_from={run}", "seed=7", f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-1000:]
    assert json.loads((run / "summary.json").read_text())["seed"] == 7
    assert rundir.foreign_files(run) == []
    aside = list(tmp_path.glob("run.replaced-*"))  # the old run, moved aside whole: nothing deleted
    assert len(aside) == 1 and tree_digest(aside[0]) == old
    assert "the run that was in" in result.stderr and str(aside[0]) in result.stderr


def test_resume_and_evaluate_take_the_config_from_the_checkpoint(finished_run, tmp_path):
    run = copy_of(finished_run, tmp_path)
    saved = checkpoint.load(run / "checkpoints" / "last.pt")["config"]
    (run / "config.yaml").write_text((run / "config.yaml").read_text()[:300])  # truncated
    result = run_cli(f"run={run}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 0 and "using the checkpoint's" in result.stderr, result.stderr[-1000:]
    result = run_cli(f"resume={run}", "collector.total_frames=1280")
    assert result.returncode == 0 and "using the checkpoint's" in result.stderr, result.stderr[-1000:]
    resumed = checkpoint.load(run / "checkpoints" / "last.pt")["config"]
    assert resumed["optim"] == saved["optim"] and resumed["loss"] == saved["loss"]
    assert resumed["logger"] == saved["logger"] and resumed["collector"]["total_frames"] == 1280


@pytest.mark.parametrize("during_eval", [False, True])
@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_in_the_last_iteration_stops_the_run(tiny_cfg, tmp_path, signum, code, during_eval):
    trainer = Trainer(tiny_cfg("eval.final_episodes=3"), tmp_path)
    if during_eval:
        evaluate = trainer._evaluate
        trainer._evaluate = lambda *a, **k: (os.kill(os.getpid(), signum), evaluate(*a, **k))[1]
    else:
        collect = trainer.collector.collect
        trainer.collector.collect = lambda: (trainer.iteration == 1 and os.kill(os.getpid(), signum), collect())[1]
    with pytest.raises(Interrupted) as error:
        trainer.train()
    assert exit_code(error.value) == code and "every frame is trained" in str(error.value)
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "interrupted"
    assert checkpoint.load(tmp_path / "checkpoints" / "last.pt")["frames"] == 512


def test_a_float32_gymnasium_env_trains_evaluates_and_exports(tmp_path):
    from conftest import compose_config
    from ppo_torchrl import evaluate, export

    run = tmp_path / "run"
    assert Trainer(compose_config(["env=gym", "env.id=Pendulum-v1", *TINY]), run).train()["status"] == "finished"
    assert evaluate.main([f"run={run}", "episodes=1"])["length_mean"] == 200
    assert export.main([f"run={run}"]).is_file()


@pytest.mark.parametrize("args, expected", [
    (["-m", "seed=range(4294967293,4294967297)"], "seed=4294967296 must be in [0, 2^32)"),  # the last of 4 jobs
    (["collector.total_frames=1000000000000000000000000000000"], "must be <= 10^12"),
    (["optim.lr=inf"], "optim.lr=inf must be a finite number"),
    (["loss.gae_lambda_typo=1"], "Key 'gae_lambda_typo' not in"),
    (["hydra.run.dir=/tmp/${oops}"], "hydra.run.dir: Interpolation key 'oops' not found"),
    (["-m", "hparams_search=optuna", "hydra.sweeper.n_trials=-1"], "hydra.sweeper.n_trials=-1 must be >= 1"),
    (["trial_seeds=[6,6]"], "trial_seeds=[6, 6] must be distinct seeds"),
    (["trial_prune_below=100"], "trial_prune_below=100.0 stops a trial of several seeds: give trial_seeds"),
])
def test_bad_values_are_refused_before_anything_runs(tmp_path, capsys, args, expected):
    where = "hydra.sweep.dir" if "-m" in args else "hydra.run.dir"
    args = [*RUN, *args] + ([] if any(a.startswith(where) for a in args) else [f"{where}={tmp_path / 'new'}"])
    code, lines = refused(args, capsys)
    assert code == 2 and len(lines) == 1 and expected in lines[0], lines
    assert not (tmp_path / "new").exists()


def test_run_dirs_with_any_characters_train_resume_and_evaluate(tmp_path):
    run = tmp_path / "ünïcode, it's \"quoted\""
    assert run_cli(*RUN, f"hydra.run.dir={run}").returncode == 0
    result = run_cli(f"resume={run}", "collector.total_frames=768")
    assert result.returncode == 0, result.stderr[-1000:]
    assert json.loads((run / "summary.json").read_text())["frames"] == 768
    assert run_cli(f"run={run}", "episodes=1", module="ppo_torchrl.evaluate").returncode == 0


def test_user_fixable_paths_are_one_line_before_any_episode(finished_run, tmp_path):
    run = copy_of(finished_run, tmp_path)
    (tmp_path / "a_file").write_text("x")
    for out in (tmp_path / "a_file", "/proc/x"):
        result = run_cli(f"run={run}", f"out={out}", module="ppo_torchrl.evaluate")
        assert result.returncode == 2 and result.stderr.startswith("error: cannot write the eval's files")
        assert result.stderr.strip().count("\n") == 0
    (run / "metrics.csv").write_text("iteration,frames\n1,abc\n")
    result = run_cli(str(run), module="ppo_torchrl.report")
    assert result.returncode == 2 and "metrics.csv is damaged" in result.stderr and "Traceback" not in result.stderr


def test_a_full_disk_or_a_filesystem_without_locks_is_one_line_exit_1(tmp_path, capsys, monkeypatch):
    full = OSError(errno.ENOSPC, "No space left on device", str(tmp_path / "checkpoints" / "last.pt"))
    assert exit_code(full) == 1
    assert message_of(full).startswith(f"error: the disk is full writing {tmp_path}/checkpoints/last.pt; free some")

    def no_locks(fd, op):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(lifecycle.fcntl, "flock", no_locks)
    with pytest.raises(SystemExit) as exit_:
        guarded(lifecycle.Lifecycle().lock, tmp_path / "run")
    line = capsys.readouterr().err.strip()
    assert exit_.value.code == 1 and line.startswith("error: cannot lock the run dir") and "local disk" in line


def test_a_signal_that_a_library_wrapped_during_imports_is_an_interrupt():
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise ImportError("while importing torch") from interrupt
    except ImportError as wrapped:
        assert exit_code(wrapped) == 130 and message_of(wrapped).startswith("interrupted:")


def test_a_killed_eval_process_is_restarted_and_the_run_finishes(tiny_cfg, tmp_path, capsys, monkeypatch):
    from ppo_torchrl.run import eval_worker

    trainer = Trainer(tiny_cfg("collector.total_frames=1024", "eval.every_frames=256", "eval.background=true"), tmp_path)
    submit = eval_worker.BackgroundEval.submit

    def submit_then_kill(self, frames, *args, **kwargs):  # the worker dies with the first eval in it
        submit(self, frames, *args, **kwargs)
        if frames == 256:
            self._process.kill()
            self._process.join()

    monkeypatch.setattr(eval_worker.BackgroundEval, "submit", submit_then_kill)
    summary = trainer.train()
    assert summary["status"] == "finished"
    assert "the background eval process died" in capsys.readouterr().err
    rows = (tmp_path / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    evals = [r.split(",")[header.index("eval/return_mean")] for r in rows[1:]]
    assert len(evals) == 4 and all(evals), evals  # every eval point has its eval, the one in flight at the kill too


def test_a_dead_workers_line_survives_a_wait_that_swallows_it():
    """TorchRL's weight-update ack wait catches any exception and logs it: the watch's error raised into it
    by SIGUSR1 was lost, and the run ended on TorchRL's own error as an internal error (seen in CI). The
    watch must give the line again to the collector's catch."""
    import multiprocessing

    from ppo_torchrl.collectors.multiprocess import WorkerWatch

    worker = multiprocessing.get_context("fork").Process(target=time.sleep, args=(60,))
    worker.start()
    watch = WorkerWatch([worker])
    try:
        swallowed = []
        os.kill(worker.pid, signal.SIGKILL)
        deadline = time.time() + 60
        while not swallowed and time.time() < deadline:
            try:
                time.sleep(0.05)  # a TorchRL wait: `except Exception` logs what it caught, then goes on
            except Exception as error:  # noqa: BLE001
                swallowed.append(str(error))
        again = watch.error()
    finally:
        watch.stop()
        worker.join(5)
    expected = f"collector worker 0 (pid {worker.pid}) died (killed by SIGKILL)"
    assert swallowed and expected in swallowed[0]
    assert again is not None and expected in str(again)


def test_a_killed_collector_worker_is_one_line_and_a_failed_status(tmp_path):
    run = tmp_path / "run"
    args = ["env=InvertedPendulum-v4", "collector.workers=2", "collector.frames_per_batch=256",
            "collector.total_frames=10000000", "eval.every_frames=0", "checkpoint.every_frames=256", "logger=none",
            "compile=false", f"hydra.run.dir={run}"]
    process = App(args, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.time() + 300  # two workers' imports on a loaded 2-core machine: minutes, not seconds
        while time.time() < deadline and not (run / "checkpoints" / "last.pt").exists() and process.poll() is None:
            time.sleep(0.2)
        assert (run / "checkpoints" / "last.pt").exists(), f"no checkpoint in time: {process.poll()=}"
        children = subprocess.run(["ps", "-ww", "-o", "pid=,args=", "--ppid", str(process.pid)], capture_output=True,
                                  text=True).stdout.splitlines()
        workers = [int(line.split()[0]) for line in children if "resource_tracker" not in line]
        assert len(workers) == 2, children  # the two collector workers, and nothing else to kill by mistake
        os.kill(workers[-1], signal.SIGKILL)
        _, err = process.communicate(timeout=120)
    finally:  # whatever failed above, the run and its workers do not outlive the test
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    line = next(l for l in err.splitlines() if l.startswith("error:"))
    assert process.returncode == 1 and f"(pid {workers[-1]}) died (killed by SIGKILL)" in line
    assert "the last checkpoint on disk is" in line and "Traceback" not in err
    assert json.loads((run / "summary.json").read_text())["status"] == "failed"


@pytest.mark.parametrize("seed", ["-5", "4294968"])
def test_evaluate_a_seed_out_of_range_is_one_line_and_writes_nothing(finished_run, tmp_path, seed):
    """Issue 47: episode i's seed is seed * 1000 + i, a 32-bit number: a seed outside that is one line, exit 2."""
    run = copy_of(finished_run, tmp_path)
    before = tree_digest(tmp_path)
    result = run_cli(f"run={run}", f"seed={seed}", "episodes=1", module="ppo_torchrl.evaluate")
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and lines[0].startswith(f"error: seed={seed} must be in 0.."), lines
    assert tree_digest(tmp_path) == before
