"""The TorchRL pipeline first-class: its checkpoints, evaluation and export agree with training,
and a user's own TorchRL transforms plug in by config."""

import json

import numpy as np
import pytest
import torch
from torchrl.envs.utils import ExplorationType, set_exploration_type

from ppo_torchrl import evaluate, export
from ppo_torchrl.run.checkpoint import load_policy
from ppo_torchrl.collectors import resolve_backend
from ppo_torchrl.envs.normalization import make_observation_normalizer
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.trainer import Trainer

CATFRAMES = "env.transforms.extra=[{_target_: torchrl.envs.CatFrames, N: 3, dim: -1, in_keys: [observation]}]"


def test_a_torchrl_checkpoint_evaluates_to_its_final_eval_and_exports_the_actors_actions(tiny_cfg, tmp_path):
    cfg = tiny_cfg("collector.backend=torchrl", "eval.final_episodes=3")
    summary = Trainer(cfg, tmp_path).train()
    loaded_cfg, ac, state = load_policy(tmp_path, "last")
    again = evaluate.evaluate_policy(loaded_cfg, ac, state["normalization"]["obs"], 3, seed=cfg.seed + 10_000)
    assert again["return_mean"] == pytest.approx(summary["eval_return_mean"])

    path = export.export_policy(loaded_cfg, ac, state["normalization"]["obs"], tmp_path / "policy.pt")
    deployed = torch.jit.load(str(path))
    raw = torch.randn(16, 4, dtype=torch.float64) * 0.3
    norm = make_observation_normalizer(loaded_cfg.env.transforms, 4, state["normalization"]["obs"], frozen=True)
    obs = torch.as_tensor(norm.apply(raw.numpy())).float()
    with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
        td = ac.actor(__import__("tensordict").TensorDict({"observation": obs}, batch_size=[16]))
    expected = torch.maximum(torch.minimum(td["action"], ac.action_high), ac.action_low)
    torch.testing.assert_close(deployed(raw.float()), expected, rtol=1e-5, atol=1e-5)


def test_backend_auto_picks_torchrl_for_extra_transforms_and_fast_refuses_them(tiny_cfg):
    assert resolve_backend(tiny_cfg()) == "fast"
    assert resolve_backend(tiny_cfg(CATFRAMES)) == "torchrl"
    with pytest.raises(ConfigError, match="needs collector.backend=torchrl"):
        resolve_backend(tiny_cfg(CATFRAMES, "collector.backend=fast"))


def test_catframes_by_config_sizes_the_networks_checkpoints_and_evaluates(tiny_cfg, tmp_path, capsys):
    trainer = Trainer(tiny_cfg(CATFRAMES), tmp_path)
    assert trainer.spec.obs_dim == 3 * 4  # InvertedPendulum's 4, three frames
    assert trainer.train()["frames"] == 512
    result = evaluate.main([f"run={tmp_path}", "episodes=2"])
    assert result["episodes"] == 2 and np.isfinite(result["return_mean"])
    with pytest.raises(ConfigError, match=r"extra\[0\] \(torchrl.envs.CatFrames\) cannot be baked"):
        export.main([f"run={tmp_path}"])
    assert json.loads((tmp_path / "summary.json").read_text())["status"] == "finished"


@pytest.mark.parametrize("entry, expected", [
    ("[{_target_: torchrl.envs.NoSuchTransform}]", "extra[0]: _target_=torchrl.envs.NoSuchTransform is not a TorchRL "
                                                   "transform this app builds"),
    ("[{_target_: torchrl.envs.CatFrames, M: 3}]", "unexpected keyword argument 'M'"),
    ("[{N: 3}]", "needs a _target_"),
    ("[{_target_: collections.OrderedDict}]", "_target_=collections.OrderedDict is not a TorchRL transform"),
])
def test_a_bad_transform_entry_is_one_line_naming_it(tiny_cfg, tmp_path, entry, expected):
    with pytest.raises(ConfigError, match=expected.replace("[", r"\[").replace("(", r"\(").replace(")", r"\)")):
        Trainer(tiny_cfg(f"env.transforms.extra={entry}"), tmp_path)
