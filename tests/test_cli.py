"""The command line as a user runs it: real subprocesses, real Hydra."""

import importlib
import json

import pytest

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


def test_help_is_the_apps_own_page():
    result = run_cli("--help")
    assert result.returncode == 0, result.stderr[-2000:]
    out = result.stdout
    assert out.startswith("ppo_torchrl: PPO on MuJoCo") and "powered by Hydra" not in out
    for command in ("-m env=Hopper-v4,Walker2d-v4 seed=1,2,3", "resume=<run dir>", "init_from=", "--cfg job",
                    "ppo_torchrl.evaluate", "ppo_torchrl.export", "ppo_torchrl.report"):
        assert command in out, command
    for group in ("env", "policy", "loss", "advantage", "optim", "collector", "logger", "eval", "checkpoint",
                  "experiment", "hparams_search"):
        assert f"\n  {group:<16}" in out, group  # one line of meaning
        assert f"\n{group}: " in out, group  # its options, as Hydra lists them
    assert "env: Ant-v4, Ant-v5" in out and "loss: a2c, clip_ppo, kl_ppo, ppo, reinforce" in out
    assert "policy.width, when set, replaces the width of every hidden layer" in out
    assert "outputs/runs/<date>/<time>_<env>_seed<seed>/" in out and "outputs/multirun/<date>/<time>/" in out
    assert "log_std_init" not in out  # the composed config ($CONFIG) is left to --cfg job


@pytest.mark.parametrize("module, names", [
    ("evaluate", ["run", "checkpoint", "episodes", "video", "seed"]),
    ("export", ["run", "checkpoint"]),
    ("report", ["<run dir or sweep dir>"]),
])
@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_entry_points_print_a_usage_page_and_exit_0(module, names, flag, capsys):
    main = importlib.import_module(f"ppo_torchrl.{module}").main
    with pytest.raises(SystemExit) as exit_:
        main(["run=/nowhere", flag] if module != "report" else [flag])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: python -m ppo_torchrl.{module} ")
    lines = out.splitlines()
    for name in names:  # each argument: its name, one line of meaning, its default
        line = next(l for l in lines if l.startswith(f"  {name} "))
        assert len(line.split(None, len(name.split()))[-1]) > 20 and line.endswith(")"), line


def test_report_help_from_the_command_line_exits_0():
    result = run_cli("--help", module="ppo_torchrl.report")
    assert result.returncode == 0 and "usage: python -m ppo_torchrl.report" in result.stdout
