import numpy as np
import pytest
import torch

from ppo_torchrl.run import checkpoint

from ppo_torchrl.run import rundir
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.trainer import Trainer


def test_round_trip_restores_weights_optimizer_and_normalization(tiny_cfg, tmp_path):
    trainer = Trainer(tiny_cfg(), tmp_path / "a")
    trainer.train()
    state = checkpoint.load(tmp_path / "a" / "checkpoints" / "last.pt")
    assert state["frames"] == 512 and state["iteration"] == 2
    assert state["spec"] == {"obs_dim": 4, "action_dim": 1}
    obs_stats = state["normalization"]["obs"]
    assert obs_stats["count"] > 512  # every observation seen updated the running stats
    np.testing.assert_allclose(obs_stats["mean"], trainer.collector.obs_stats()["mean"])

    fresh = Trainer(tiny_cfg("seed=99"), tmp_path / "b")
    fresh.ac.actor.load_state_dict(state["actor"])
    fresh.ac.critic.load_state_dict(state["critic"])
    fresh.optimizer.load_state_dict(state["optimizer"])
    fresh.collector.load_state_dict(state["normalization"])
    for p, q in zip(fresh.params, trainer.params):
        torch.testing.assert_close(p, q)
    np.testing.assert_allclose(fresh.collector.obs_stats()["var"], obs_stats["var"])
    assert fresh.collector.state.reward_norm.returns.stats.count == state["normalization"]["return"]["count"]
    assert fresh.optimizer.state_dict()["state"][0]["step"] == trainer.optimizer.state_dict()["state"][0]["step"]


def test_keeps_last_k_and_best(tiny_cfg, tmp_path):
    Trainer(tiny_cfg("collector.total_frames=1024", "checkpoint.keep_last=2", "eval.every_frames=256",
                     "eval.episodes=1"), tmp_path).train()
    ckpts = sorted(p.name for p in (tmp_path / "checkpoints").glob("frames_*.pt"))
    assert ckpts == ["frames_0000000768.pt", "frames_0000001024.pt"]
    assert (tmp_path / "checkpoints" / "best.pt").is_file()


def test_atomic_write_leaves_the_old_file_when_the_writer_fails(tmp_path):
    path = tmp_path / "last.pt"
    checkpoint.save(path, {"actor": {}, "frames": 1})

    def broken(f):
        f.write(b"partial")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        rundir.atomic_write_bytes(path, broken)
    assert checkpoint.load(path)["frames"] == 1
    assert [p.name for p in tmp_path.iterdir()] == ["last.pt"]  # no temp file left behind


def test_corrupt_checkpoint_is_a_clear_error(tmp_path):
    bad = tmp_path / "last.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ConfigError, match="corrupt"):
        checkpoint.load(bad)
    with pytest.raises(ConfigError, match="does not exist"):
        checkpoint.load(tmp_path / "missing.pt")
