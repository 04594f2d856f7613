"""Issue 61 item 3: the Python API (ppo_torchrl.train / load / evaluate_run). The README's example is run as
written; a bad override is ConfigError before anything is written; predict is the exported policy's action."""

from __future__ import annotations

import re

import numpy as np
import pytest
import torch

import ppo_torchrl
from ppo_torchrl.errors import ConfigError

from conftest import ROOT, TINY


def readme_example() -> str:
    text = (ROOT / "README.md").read_text()
    section = text.split("**From Python**", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.S).group(1)


def test_the_readme_example_runs_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    exec(compile(readme_example(), "README.md", "exec"), {})
    out = capsys.readouterr().out.split()
    assert out[0] == "finished" and (tmp_path / "outputs" / "api_demo" / "checkpoints" / "last.pt").is_file()
    assert float(out[-1]) > 0  # the eval's mean return


def test_a_bad_override_is_one_config_error_and_writes_nothing(tmp_path):
    with pytest.raises(ConfigError, match="colector"):
        ppo_torchrl.train(["env=InvertedPendulum-v4", "colector.total_frames=512"], run_dir=tmp_path / "run")
    with pytest.raises(ConfigError, match="as arguments"):
        ppo_torchrl.train(["resume=somewhere"], run_dir=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_predict_is_the_exported_policys_action_and_resume_extends(tmp_path):
    run = ppo_torchrl.train(["env=InvertedPendulum-v4", *TINY], run_dir=tmp_path / "run")
    assert run.status == "finished" and run.summary["frames"] == 512
    policy = ppo_torchrl.load(run.dir, checkpoint="last")
    obs = np.random.default_rng(0).normal(size=(3, 4))
    from ppo_torchrl import export

    export.main([f"run={run.dir}", "checkpoint=last"])
    scripted = torch.jit.load(str(run.dir / "policy.pt"))
    expected = scripted(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    assert policy.predict(obs).shape == (3, 1) and np.allclose(policy.predict(obs), expected, atol=1e-6)
    result = ppo_torchrl.evaluate_run(run.dir, episodes=2, seed=3, checkpoint="last")
    assert len(result["returns"]) == 2
    longer = ppo_torchrl.train(["collector.total_frames=768"], resume=run.dir)
    assert longer.dir == run.dir and longer.summary["frames"] == 768
