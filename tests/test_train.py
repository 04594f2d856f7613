"""Short real training runs on InvertedPendulum-v4 through every loss x policy head."""

import csv
import json
import multiprocessing

import pytest
import torch

from ppo_torchrl.collectors.collection import Collection
from ppo_torchrl.collectors.fast import FastCollector
from ppo_torchrl.rl.losses import LOSS_INPUT_KEYS
from ppo_torchrl.rl.minibatch import EagerStep, FusedStep
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
    collector: Collection = trainer.collector
    assert isinstance(collector.collector, FastCollector)  # a torchrl.collectors.Collector
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


def _steps_from_one_state(trainer, make_step, minibatches, lrs=None):
    """Run `make_step()` over the minibatches from the trainer's initial weights and a fresh optimizer
    (at lr 1e-3, or at lrs[i] for minibatch i)."""
    start = [p.detach().clone() for p in trainer.params]
    with torch.no_grad():
        for p, p0 in zip(trainer.params, start):
            p.copy_(p0)
    trainer.optimizer.state.clear()
    trainer.optimizer.param_groups[0]["lr"] = 1e-3
    torch.manual_seed(0)
    step = make_step()
    rows = []
    for i, mb in enumerate(minibatches):
        if lrs is not None:
            trainer.optimizer.param_groups[0]["lr"] = lrs[i]
        rows.append(step(mb.clone())[0])
    metrics = torch.stack(rows)
    after = [p.detach().clone() for p in trainer.params]
    state = {k: {n: v.clone() for n, v in s.items()} for k, s in trainer.optimizer.state_dict()["state"].items()}
    with torch.no_grad():
        for p, p0 in zip(trainer.params, start):
            p.copy_(p0)
    return metrics, after, state, step.metric_keys


@pytest.mark.parametrize("overrides", [[], ["loss=a2c", "policy=tanh_normal", "loss.entropy_coef=0.01",
                                            "optim=adamw", "optim.weight_decay=0.01"],
                                       ["loss=ppo", "optim.weight_decay=0.01", "optim.max_grad_norm=null"]])
def test_fused_step_is_the_eager_step(tiny_cfg, tmp_path, overrides):
    """FusedStep (one function: torch.func gradients, clip, Adam on the optimizer's state) takes the same
    steps as the TorchRL loss + backward + clip_grad_norm_ + torch.optim; here run eagerly, compiled below."""
    trainer = Trainer(tiny_cfg("compile=false", *overrides), tmp_path)
    batch = trainer.collector.collect()
    trainer.prepare(batch)
    flat = batch.reshape(-1).select(*LOSS_INPUT_KEYS, strict=False)
    minibatches = [flat[i * 32:(i + 1) * 32] for i in range(6)]
    args = (trainer.loss_module, trainer.optimizer, trainer.params, True, trainer.cfg.optim.max_grad_norm)
    eager = _steps_from_one_state(trainer, lambda: EagerStep(*args), minibatches)
    fused = _steps_from_one_state(trainer, lambda: FusedStep(*args, compile=False), minibatches)
    assert eager[3] == fused[3] and ("loss_objective" in fused[3] or "loss_actor" in fused[3])
    torch.testing.assert_close(fused[0], eager[0], rtol=1e-4, atol=1e-5)
    for a, b in zip(fused[1], eager[1]):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    assert any(not torch.equal(a, p) for a, p in zip(fused[1], trainer.params)), "no parameter moved"
    for key in eager[2]:
        for name in ("step", "exp_avg", "exp_avg_sq"):
            torch.testing.assert_close(fused[2][key][name], eager[2][key][name], rtol=1e-4, atol=1e-7)


def test_fused_step_takes_no_step_from_a_non_finite_loss(tiny_cfg, tmp_path):
    trainer = Trainer(tiny_cfg("compile=false"), tmp_path)
    batch = trainer.collector.collect()
    trainer.prepare(batch)
    minibatch = batch.reshape(-1)[:64].select(*LOSS_INPUT_KEYS, strict=False).clone()
    minibatch["advantage"][3] = float("nan")
    step = FusedStep(trainer.loss_module, trainer.optimizer, trainer.params, True, 0.5, compile=False)
    before = [p.detach().clone() for p in trainer.params]
    metrics, grad_norm = step(minibatch)
    assert not torch.isfinite(metrics[0] + grad_norm)
    assert all(torch.equal(a, p) for a, p in zip(before, trainer.params))
    assert all(float(s["step"]) == 0 for s in trainer.optimizer.state.values())


def test_compiled_run_matches_its_eager_step(tiny_cfg, tmp_path):
    trainer = Trainer(tiny_cfg("compile=true"), tmp_path)
    assert isinstance(trainer.minibatch_step, FusedStep)
    batch = trainer.collector.collect()
    trainer.prepare(batch)
    flat = batch.reshape(-1).select(*LOSS_INPUT_KEYS, strict=False)
    minibatches = [flat[i * 64:(i + 1) * 64] for i in range(3)]
    lrs = [1e-3, 5e-4, 3e-3]  # the compiled step guards on tensors only: a new lr (a tensor) must still count
    args = (trainer.loss_module, trainer.optimizer, trainer.params, True, trainer.cfg.optim.max_grad_norm)
    eager = _steps_from_one_state(trainer, lambda: FusedStep(*args, compile=False), minibatches, lrs)
    compiled = _steps_from_one_state(trainer, lambda: trainer.minibatch_step, minibatches, lrs)
    torch.testing.assert_close(compiled[0], eager[0], rtol=1e-4, atol=1e-5)
    for a, b in zip(compiled[1], eager[1]):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-6)
    assert trainer.train()["status"] == "finished"


def test_compile_auto_only_for_long_runs(tiny_cfg):
    assert not use_compile(tiny_cfg())
    assert use_compile(tiny_cfg("collector.total_frames=1000000"))
    assert not use_compile(tiny_cfg("collector.total_frames=1000000", "compile=false"))
    assert use_compile(tiny_cfg("compile=true"))
    assert not use_compile(tiny_cfg("collector.total_frames=1000000", "loss=kl_ppo"))  # not compilable


def test_background_eval_writes_what_the_in_line_eval_writes(tiny_cfg, tmp_path):
    """eval.background=true: the worker process evaluates the same weights with the same seeds; each row
    waits for its eval, so metrics.csv holds the same values (timings aside) in the same order. The
    final eval's episodes are shared between the trainer and the worker: the same figures too."""
    tables = {}
    for mode in ("false", "true"):
        cfg = tiny_cfg("collector.total_frames=1024", "eval.every_frames=512", "eval.episodes=2",
                       "eval.final_episodes=3", f"eval.background={mode}")
        trainer = Trainer(cfg, tmp_path / mode)
        assert trainer.train()["status"] == "finished"
        assert trainer.evals is None if mode == "false" else trainer.evals is not None
        with open(tmp_path / mode / "metrics.csv") as f:
            tables[mode] = [{k: v for k, v in row.items() if k not in ("time_s", "sps")} for row in csv.DictReader(f)]
    assert [row["eval/return_mean"] != "" for row in tables["true"]] == [False, True, False, True]
    assert tables["true"] == tables["false"]
    assert (tmp_path / "true" / "checkpoints" / "best.pt").is_file()
    assert not multiprocessing.active_children()


def test_evals_and_the_logger_do_not_change_training(tiny_cfg, tmp_path):
    """The same seed and config train the same whatever eval.every_frames (in line or in a second process)
    or the logger: evals and logging draw from no training random stream."""
    tables = {}
    runs = {"plain": [], "evals": ["eval.every_frames=256", "eval.episodes=2"],
            "background": ["eval.every_frames=256", "eval.episodes=2", "eval.background=true"], "csv": ["logger=csv"]}
    for name, extra in runs.items():
        Trainer(tiny_cfg("seed=5", "collector.total_frames=1024", *extra), tmp_path / name).train()
        with open(tmp_path / name / "metrics.csv") as f:
            tables[name] = [{k: v for k, v in row.items() if not k.startswith("eval/") and k not in ("time_s", "sps")}
                            for row in csv.DictReader(f)]
    assert len(tables["plain"]) == 4
    assert tables["evals"] == tables["plain"] and tables["background"] == tables["plain"] and tables["csv"] == tables["plain"]
