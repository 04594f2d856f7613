"""The command line as a user runs it: real subprocesses, real Hydra."""

import json

from conftest import TINY, run_cli


def test_multirun_over_seeds(tmp_path):
    result = run_cli("-m", "env=InvertedPendulum-v4", "seed=1,2", *TINY, f"hydra.sweep.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    summaries = sorted(tmp_path.glob("*/summary.json"))
    assert len(summaries) == 2
    seeds = sorted(json.loads(p.read_text())["seed"] for p in summaries)
    assert seeds == [1, 2]
    for p in summaries:
        assert (p.parent / "config.yaml").is_file() and (p.parent / "metrics.csv").is_file()


def test_generic_env_trains_another_gymnasium_id(tmp_path):
    result = run_cli("env=gym", "env.id=Swimmer-v4", *TINY, f"hydra.run.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    assert json.loads((tmp_path / "summary.json").read_text())["env"] == "Swimmer-v4"
