"""Short real training runs on InvertedPendulum-v4 through every loss x policy head."""

import json

import pytest
import torch

from ppo_torchrl.collectors import FastCollector
from ppo_torchrl.losses import make_loss_step
from ppo_torchrl.losses import LOSS_INPUT_KEYS
from ppo_torchrl.trainer import Trainer, use_compile

LOSSES = ["clip_ppo", "kl_ppo", "ppo", "a2c", "reinforce"]
HEADS = ["normal", "tanh_normal"]
SUMMARY_KEYS = {"env", "seed", "frames", "wall_s", "sps", "eval_return_mean", "eval_return_std", "train_return_last100"}


@pytest.mark.parametrize("head", HEADS)
@pytest.mark.parametrize("loss", LOSSES)
def test_every_loss_and_head_trains(tiny_cfg, tmp_path, loss, head):
    trainer = Trainer(tiny_cfg(f"loss={loss}", f"policy={head}"), tmp_path)
    before = [p.detach().clone() for p in trainer.params]
    summary = trainer.train()
    assert summary["frames"] == 512
    assert any(not torch.equal(a, b) for a, b in zip(before, trainer.params)), "no parameter moved"
    on_disk = json.loads((tmp_path / "summary.json").read_text())
    assert SUMMARY_KEYS <= on_disk.keys() and on_disk["status"] == "finished"
    assert on_disk["eval_return_mean"] is not None and on_disk["sps"] > 0
    assert (tmp_path / "checkpoints" / "last.pt").is_file()
    header = (tmp_path / "metrics.csv").read_text().splitlines()[0].split(",")
    for column in ("train/approx_kl", "train/clipfrac", "train/explained_variance", "train/entropy", "lr",
                   "policy/loc_mean", "policy/scale_mean", "sps", "loss/critic"):
        assert column in header


@pytest.mark.parametrize("num_envs", [1, 2])
def test_torchrl_collector_backend_trains(tiny_cfg, tmp_path, num_envs):
    trainer = Trainer(tiny_cfg("collector.backend=torchrl", f"collector.num_envs={num_envs}"), tmp_path)
    summary = trainer.train()
    assert summary["frames"] == 512 and summary["train_return_last100"] is not None
    assert trainer.collector.obs_stats()["mean"].shape == (4,)  # one set of stats for all envs
    assert summary["eval_return_mean"] is not None


def test_several_envs_and_shared_trunk(tiny_cfg, tmp_path):
    summary = Trainer(tiny_cfg("collector.num_envs=4", "policy.shared_trunk=true"), tmp_path).train()
    assert summary["frames"] == 512


@pytest.mark.parametrize("obs_norm, reward_norm", [("fixed", "scale"), ("none", "none")])
def test_transform_options(tiny_cfg, tmp_path, obs_norm, reward_norm):
    cfg = tiny_cfg(f"env.transforms.obs_norm={obs_norm}", f"env.transforms.reward_norm={reward_norm}",
                   "env.transforms.reward_scale=0.1")
    assert Trainer(cfg, tmp_path).train()["frames"] == 512


def test_fast_collector_batch_layout_and_truncation(tiny_cfg):
    cfg = tiny_cfg("collector.num_envs=2", "env.max_episode_steps=50")
    trainer = Trainer(cfg, "/tmp/unused")
    collector: FastCollector = trainer.collector
    batch = collector.collect()
    assert batch.batch_size == torch.Size([2, 128])
    nxt = batch["next"]
    assert torch.equal(nxt["done"], nxt["terminated"] | nxt["truncated"])
    # the pendulum rarely survives 50 steps early on, but any survivor is truncated, not terminated
    assert not (nxt["terminated"] & nxt["truncated"]).any()
    # observation[t+1] is next.observation[t] unless an episode ended at t
    cont = ~nxt["done"][:, :-1, 0]
    torch.testing.assert_close(batch["observation"][:, 1:][cont], nxt["observation"][:, :-1][cont])
    # raw episode returns: InvertedPendulum pays 1 per step, so return == length
    for ret, length in collector.pop_episodes():
        assert ret == length
    collector.close()


def test_same_seed_same_first_iterations(tiny_cfg, tmp_path):
    rows = []
    for name in ("a", "b"):
        Trainer(tiny_cfg("seed=3"), tmp_path / name).train()
        rows.append((tmp_path / name / "metrics.csv").read_text().splitlines()[1].split(",")[4:])
    assert rows[0] == rows[1]


@pytest.mark.parametrize("overrides", [[], ["loss=a2c", "policy=tanh_normal"]])
def test_compiled_loss_step_matches_eager(tiny_cfg, tmp_path, overrides):
    trainer = Trainer(tiny_cfg("compile=true", *overrides), tmp_path)
    batch = trainer.collector.collect()
    trainer.prepare(batch)
    minibatch = batch.reshape(-1)[:64].select(*LOSS_INPUT_KEYS, strict=False)
    eager_loss, eager_out = make_loss_step(trainer.loss_module, True)(minibatch.clone())
    compiled_loss, compiled_out = trainer.loss_step(minibatch.clone())
    torch.testing.assert_close(compiled_loss, eager_loss, rtol=1e-4, atol=1e-5)
    for key in eager_out.keys():
        torch.testing.assert_close(compiled_out.get(key), eager_out.get(key), rtol=1e-4, atol=1e-5)
    assert trainer.train()["status"] == "finished"


def test_compile_auto_only_for_long_runs(tiny_cfg):
    assert not use_compile(tiny_cfg())
    assert use_compile(tiny_cfg("collector.total_frames=1000000"))
    assert not use_compile(tiny_cfg("collector.total_frames=1000000", "compile=false"))
    assert use_compile(tiny_cfg("compile=true"))
    assert not use_compile(tiny_cfg("collector.total_frames=1000000", "loss=kl_ppo"))  # not compilable
