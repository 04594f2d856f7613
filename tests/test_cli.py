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


def test_unknown_env_file_lists_the_available_ones_and_the_generic_form():
    result = run_cli("env=Hoper-v4")
    assert result.returncode != 0
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr
    assert "Hopper-v4" in lines[0] and "env=gym env.id=Hoper-v4" in lines[0]


def test_generic_env_with_unregistered_id_is_one_line(tmp_path):
    result = run_cli("env=gym", "env.id=NoSuchEnv-v0", f"hydra.run.dir={tmp_path}")
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert "NoSuchEnv-v0" in result.stderr.strip().splitlines()[-1]


def test_out_of_range_value_is_one_line(tmp_path):
    result = run_cli("env=InvertedPendulum-v4", "optim.lr=-1", f"hydra.run.dir={tmp_path}")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith("error: optim.lr=-1.0 must be > 0")


def test_generic_env_trains_another_gymnasium_id(tmp_path):
    result = run_cli("env=gym", "env.id=Swimmer-v4", *TINY, f"hydra.run.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    assert json.loads((tmp_path / "summary.json").read_text())["env"] == "Swimmer-v4"
