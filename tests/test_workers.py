"""collector.workers > 1 (TorchRL's MultiSyncCollector) and collector.distributed=ray: exact batches,
one set of statistics, the learner's weights in every worker, checkpoints, and a clean Ctrl-C."""

import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from conftest import ROOT, TINY, App, run_cli
from ppo_torchrl import evaluate, export
from ppo_torchrl.envs.normalization import pool
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.trainer import Trainer
from ppo_torchrl.collectors.multiprocess import warn_if_oversubscribed
from ppo_torchrl.validation import validate_config

def descendants(pid: int) -> list:
    """Process ids under `pid` (`pgrep -P`, recursively)."""
    found = subprocess.run(["pgrep", "-P", str(pid)], capture_output=True, text=True).stdout.split()
    return [int(c) for c in found] + [d for c in found for d in descendants(int(c))]


def alive(pid: int) -> bool:
    """Running (a zombie waiting for its reaper is not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


WORKERS = ["collector.workers=2", "collector.num_envs=2"]  # 256 frames: 2 workers x 2 envs x 64 steps


def test_pooling_is_the_exact_mean_and_variance_of_everything_the_workers_saw():
    rng = np.random.default_rng(0)
    seen, worker_a, worker_b = rng.normal(3, 2, (50, 4)), rng.normal(-1, 1, (30, 4)), rng.normal(5, 3, (70, 4))

    def stats(x):
        return {"mean": x.mean(0), "var": x.var(0), "count": float(len(x))}

    merged = pool(stats(seen), [stats(np.concatenate([seen, w])) for w in (worker_a, worker_b)])
    everything = np.concatenate([seen, worker_a, worker_b])
    assert merged["count"] == 150
    np.testing.assert_allclose(merged["mean"], everything.mean(0), rtol=1e-12)
    np.testing.assert_allclose(merged["var"], everything.var(0), rtol=1e-10)


HAS_RAY = importlib.util.find_spec("ray") is not None
RAY = pytest.param("collector.distributed=ray", marks=pytest.mark.skipif(not HAS_RAY, reason="ray is not installed"))


@pytest.mark.parametrize("distributed", ["collector.distributed=null", RAY])
@pytest.mark.parametrize("backend", ["fast", "torchrl"])
def test_workers_collect_exact_on_policy_batches_and_share_one_set_of_stats(tiny_cfg, tmp_path, distributed, backend):
    """TorchRL's MultiSyncCollector / RayCollector building FastCollector (or TorchRL's Collector) in each worker."""
    cfg = tiny_cfg(*WORKERS, distributed, f"collector.backend={backend}")
    trainer = Trainer(cfg, tmp_path)
    collector = trainer.collector
    try:
        assert type(collector.collector).__name__ == ("RayCollector" if "ray" in distributed else "MultiSyncCollector")
        batches = [collector.collect() for _ in range(2)]
        assert [tuple(b.shape) for b in batches] == [(4, 64), (4, 64)]  # exactly frames_per_batch each
        dones = sum(int(b.get(("next", "done")).sum()) for b in batches)
        obs = collector.obs_stats()
        # every observation counted once: each env's first reset, every step and every reset after a done
        # (TorchRL's Collector in a MultiSyncCollector worker resets each env twice before its first step: the
        # first reset, which no policy acts on, is not counted)
        assert obs["count"] == 4 + 512 + dones and np.isfinite(obs["mean"]).all() and (obs["var"] > 0).all()
        returns = collector.state_dict()["return"]
        assert returns["count"] == pytest.approx(512 + 1e-4)  # the prior, then each frame's return once

        with torch.no_grad():  # an "update": the next batch must be collected with these weights
            for name, p in trainer.ac.actor.named_parameters():
                p.fill_(-30.0 if name.endswith("log_std") else 0.0)  # mean 0, std e^-30: every action ~0
        batch = collector.collect()
        assert batch["action"].abs().max() < 1e-6  # every worker drew with the learner's new weights
        from ppo_torchrl.internals import OWN, env_snapshot

        mine = collector.state.snapshot(positions=False)  # the merged set, in the main process's EnvState
        _, workers = collector._worker_states()
        # every worker's EnvState holds where each env is; each collector adds its own RNG (internals.OWN)
        assert all(set(w[OWN]) == ({"rng"} if backend == "fast" else {"torch_rng"}) for w in workers)
        assert len(workers) == 2
        for worker in workers:
            theirs = env_snapshot(worker, collector._key)
            assert len(theirs["positions"]["envs"]) == 2  # collector.num_envs in this worker
            for kind in ("obs", "reward"):  # the observation and return statistics
                for name in set(mine[kind]) - {"returns", "layout"}:
                    torch.testing.assert_close(torch.as_tensor(theirs[kind][name]), torch.as_tensor(mine[kind][name]))
                assert theirs[kind].get("layout") == mine[kind].get("layout")  # the layout they scale (layout.py)
    finally:
        collector.close()


def test_a_workers_run_checkpoints_evaluates_exports_and_resumes(tiny_cfg, tmp_path):
    cfg = tiny_cfg(*WORKERS, "eval.final_episodes=2")
    summary = Trainer(cfg, tmp_path).train()
    assert summary["frames"] == 512 and summary["status"] == "finished"
    assert np.isfinite(summary["eval_return_mean"])
    again = evaluate.main([f"run={tmp_path}", "checkpoint=last", "episodes=2", f"seed={cfg.seed + 10_000}"])
    assert again["return_mean"] == pytest.approx(summary["eval_return_mean"])
    assert export.main([f"run={tmp_path}"]).is_file()

    from ppo_torchrl.run.checkpoint import load
    from ppo_torchrl.run.lifecycle import resume_config

    state = load(tmp_path / "checkpoints" / "last.pt")
    assert state["normalization"]["collector"] is not None and state["normalization"]["return"] is not None
    resumed = Trainer(resume_config(tmp_path, ["collector.total_frames=768"], state), tmp_path, resume=state)
    assert resumed.collector.obs_stats()["count"] == state["normalization"]["obs"]["count"]
    assert resumed.train()["frames"] == 768


@pytest.mark.parametrize("overrides, expected", [
    (["collector.workers=0"], "collector.workers=0 must be >= 1"),
    (["collector.distributed=slurm"], "collector.distributed='slurm' is not known; use null (local processes) or ray"),
    (["collector.workers=3"], "collector.frames_per_batch=256 must be divisible by collector.workers x collector.num_envs=3 x 1"),
    (["collector.ray_address=auto"], "collector.ray_address=auto needs collector.distributed=ray"),
])
def test_bad_worker_settings_are_one_line_errors(tiny_cfg, overrides, expected):
    with pytest.raises(ConfigError) as info:
        validate_config(tiny_cfg(*overrides))
    assert expected in str(info.value) and "\n" not in str(info.value)


def test_ray_missing_is_one_line_naming_the_install(tiny_cfg, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real(name, *a))
    with pytest.raises(ConfigError, match=r'needs Ray, which is not installed: pip install -e "\.\[ray\]"'):
        validate_config(tiny_cfg("collector.distributed=ray", "collector.workers=2"))


def test_workers_zero_on_the_command_line_is_exit_2_and_one_line(tmp_path):
    result = run_cli("env=InvertedPendulum-v4", "collector.workers=0", f"hydra.run.dir={tmp_path}/run")
    assert result.returncode == 2
    assert result.stderr.strip().splitlines() == ["error: collector.workers=0 must be >= 1"]


def test_more_workers_than_cores_is_one_warning_line(tiny_cfg, capsys):
    warn_if_oversubscribed(tiny_cfg(f"collector.workers={(os.cpu_count() or 1) + 1}").collector)
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: collector.workers=")
    warn_if_oversubscribed(tiny_cfg("collector.workers=1").collector)
    assert capsys.readouterr().err == ""


def test_ctrl_c_during_a_workers_run_saves_exits_130_leaves_no_workers_and_resumes(tmp_path):
    run_dir = tmp_path / "run"
    args = ["env=InvertedPendulum-v4", *WORKERS, "collector.frames_per_batch=256", "collector.total_frames=100000",
            "loss.epochs=1", "eval.every_frames=0", "eval.final_episodes=0", "checkpoint.every_frames=0",
            "logger=none", f"hydra.run.dir={run_dir}"]
    proc = App(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.time() + 120
        metrics = run_dir / "metrics.csv"
        while time.time() < deadline and not (metrics.is_file() and len(metrics.read_text().splitlines()) > 2):
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.2)
        workers = descendants(proc.pid)
        assert len(workers) >= 2
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole process group
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("interrupted: checkpoint at frame")
    assert (run_dir / "checkpoints" / "last.pt").is_file()
    deadline = time.time() + 10
    while time.time() < deadline and any(alive(p) for p in workers):
        time.sleep(0.2)
    assert not [p for p in workers if alive(p)]
    frames = json.loads((run_dir / "summary.json").read_text())["frames"]

    result = run_cli(f"resume={run_dir}", f"collector.total_frames={frames + 512}")
    assert result.returncode == 0, result.stderr
    assert json.loads((run_dir / "summary.json").read_text())["frames"] == frames + 512


@pytest.mark.skipif(not HAS_RAY, reason="ray is not installed")
def test_an_unreachable_ray_address_is_one_line(tiny_cfg, tmp_path):
    with pytest.raises(ConfigError, match=r"collector.ray_address=127.0.0.1:1: no Ray head answers there"):
        Trainer(tiny_cfg("collector.distributed=ray", "collector.ray_address=127.0.0.1:1", *WORKERS), tmp_path)
