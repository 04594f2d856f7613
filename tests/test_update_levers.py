"""Issue 75's levers of the update: advantages recomputed before every epoch (advantage.recompute) and the KL
early stop (loss.stop_kl), on a real env and the real trainer."""

import pytest
import torch

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.trainer import Trainer
from ppo_torchrl.validation import validate_config

WHOLE = ["collector.total_frames=256", "loss.minibatch_size=null", "compile=false"]


def test_recomputed_advantages_are_those_of_the_critic_the_first_epoch_left(tiny_cfg, tmp_path):
    """epochs=2, one minibatch each: the second epoch trains on GAE of the critic after the first (a one-epoch
    trainer of the same seed gives that critic); value clipping's old values stay the collected ones."""
    once = Trainer(tiny_cfg(*WHOLE, "loss.epochs=1"), tmp_path / "once")
    twice = Trainer(tiny_cfg(*WHOLE, "loss.epochs=2", "advantage.recompute=true"), tmp_path / "twice")
    a, b = once.collector.collect(), twice.collector.collect()
    torch.testing.assert_close(a.get("observation"), b.get("observation"), rtol=0, atol=0)
    once.update(a)
    collected = b.clone()
    twice.prepare(collected)  # the advantages a batch starts the update with
    twice.update(b)
    with torch.no_grad():
        once.advantage(a)  # GAE of the critic as the first epoch left it
    torch.testing.assert_close(b.get("advantage"), a.get("advantage"), rtol=1e-5, atol=1e-6)
    assert not torch.allclose(b.get("advantage"), collected.get("advantage"), rtol=1e-3, atol=1e-4)
    torch.testing.assert_close(b.get("state_value"), collected.get("state_value"), rtol=0, atol=0)
    once.collector.close()
    twice.collector.close()


def test_the_kl_early_stop_skips_the_rest_of_the_batchs_epochs(tiny_cfg, tmp_path):
    """A stop_kl any step passes: one epoch of 4 minibatches is taken, not 2 x 4; a generous one runs them all."""
    steps = {}
    for name, stop in (("tight", 1e-12), ("loose", 10.0)):
        trainer = Trainer(tiny_cfg("collector.total_frames=256", "compile=false", f"loss.stop_kl={stop}"),
                          tmp_path / name)
        stats = trainer.update(trainer.collector.collect())
        steps[name] = (stats["train/epochs"], int(trainer.optimizer.state_dict()["state"][0]["step"]))
        trainer.collector.close()
    assert steps == {"tight": (1, 4), "loose": (2, 8)}


@pytest.mark.parametrize("overrides, expected", [
    (["loss.stop_kl=0"], "loss.stop_kl=0.0 must be > 0"),
    (["loss=a2c", "loss.stop_kl=0.02"], "loss.stop_kl needs a loss that measures its KL"),
    (["advantage=mc", "advantage.recompute=true"], "advantage.recompute=true recomputes GAE"),
])
def test_the_levers_bad_values_are_one_clear_error(tiny_cfg, overrides, expected):
    with pytest.raises(ConfigError, match=expected):
        validate_config(tiny_cfg(*overrides), build_env=False)


def test_a_run_with_the_kl_stop_logs_its_epochs_per_update(tiny_cfg, tmp_path):
    import csv

    Trainer(tiny_cfg("loss.stop_kl=1e-12"), tmp_path).train()
    with open(tmp_path / "metrics.csv") as f:
        rows = list(csv.DictReader(f))
    assert [row["train/epochs"] for row in rows] == ["1", "1"]


def test_the_sb3_peer_row_gets_every_value_sb3_has_a_knob_for_and_names_the_rest():
    """benchmarks/sb3_peer.py (issue 75 item 3): HalfCheetah's env file, given to SB3's PPO: its batch, minibatch,
    epochs, constant lr, gamma, lambda, clip, coefficients, layers, activation, init and normalization; what SB3 lacks
    (the recompute lever) listed, not dropped in silence; a loss SB3's PPO is not, refused in one line."""
    import sys

    from conftest import ROOT, compose_config

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from sb3_peer import sb3_settings

    ppo, norm, lacks = sb3_settings(compose_config(["env=HalfCheetah-v4", "advantage.recompute=true"]))
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"], ppo["learning_rate"]) == (512, 64, 20, 2.0633e-05)
    assert (ppo["gamma"], ppo["gae_lambda"], ppo["clip_range"], ppo["vf_coef"], ppo["max_grad_norm"]) == \
        (0.98, 0.92, 0.1, 0.58096, 0.8)
    kwargs = ppo["policy_kwargs"]
    assert kwargs["net_arch"] == {"pi": [256, 256], "vf": [256, 256]} and kwargs["activation_fn"] is torch.nn.ReLU
    assert (kwargs["ortho_init"], kwargs["log_std_init"]) == (False, -2.0)
    assert norm == {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0, "gamma": 0.98,
                    "epsilon": 1e-8}
    assert lacks == ["advantage.recompute=true (SB3: GAE once per batch)"]
    hopper, _, none = sb3_settings(compose_config(["env=Hopper-v4"]))
    assert hopper["learning_rate"](1.0) == 2e-4 and hopper["learning_rate"](0.5) == 1e-4 and none == []
    assert hopper["policy_kwargs"]["net_arch"] == {"pi": [128, 128], "vf": [128, 128]}
    with pytest.raises(ConfigError, match="clipped objective only"):
        sb3_settings(compose_config(["env=Hopper-v4", "loss=a2c"]))


def test_the_levers_table_names_a_levers_override_from_its_records_config_when_hydra_left_none():
    """Round 4's HalfCheetah E0 records (summary.json and config.yaml, no .hydra/) showed an empty overrides cell: the
    cell is now the keys whose values differ from the base's config, and the decision is the PLAN's rule."""
    import sys

    from conftest import ROOT

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from levers_table import table

    runs = ROOT / "results" / "quality_1m_round4_tuning_2026-12-02" / "runs"
    text = table([("HalfCheetah-v4", "base", runs / "HalfCheetah-v4_base"), ("HalfCheetah-v4", "E0", runs / "HalfCheetah-v4_E0")])
    row = next(line for line in text.splitlines() if line.startswith("| E0 |"))
    assert "`loss.entropy_coef=0.0`" in row and "rejected (+288 against a margin of 791" in row, row
