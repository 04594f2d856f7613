"""The command line as a user runs it: real subprocesses, real Hydra."""

import importlib
import json
import subprocess
import sys

import pytest

from conftest import ROOT, TINY, run_cli


def test_multirun_over_seeds(tmp_path):
    result = run_cli("-m", "env=InvertedPendulum-v4", "seed=1,2", *TINY, f"hydra.sweep.dir={tmp_path}")
    assert result.returncode == 0, result.stderr[-2000:]
    summaries = sorted(tmp_path.glob("*/summary.json"))
    assert [p.parent.name for p in summaries] == ["0_seed=1", "1_seed=2"]  # each job's dir: what varies
    seeds = sorted(json.loads(p.read_text())["seed"] for p in summaries)
    assert seeds == [1, 2]
    for p in summaries:
        assert (p.parent / "config.yaml").is_file() and (p.parent / "metrics.csv").is_file()
    progress = [line for line in result.stderr.splitlines() if "frames " in line and "| sps" in line]
    assert progress and all(line.startswith(("[#0] frames", "[#1] frames")) for line in progress)
    line = result.stderr.splitlines()[-1]  # the sweep's last line: where it is and the command that compares the runs
    assert line.startswith(f"sweep: 2 of 2 runs finished in {tmp_path}; compare them: ")
    pasted = subprocess.run(line.split("compare them: ")[1], shell=True, cwd=ROOT, capture_output=True, text=True)
    assert pasted.returncode == 0, pasted.stderr[-2000:]
    assert "| 1 2 | 512 |" in (tmp_path / "sweep_report.md").read_text()


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


def test_the_wrong_python_is_one_line_that_names_the_right_one():
    # -S: no site-packages, as a checkout's system Python (ppo_torchrl imports from the working dir, hydra does not)
    result = subprocess.run([sys.executable, "-S", "-m", "ppo_torchrl", "env=Hopper-v4"], capture_output=True,
                            text=True, cwd=ROOT, timeout=60)
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: ")
    assert "it is not the project's Python; run .venv/bin/python -m ppo_torchrl ... (or make train)" in result.stderr


def test_a_run_ends_with_one_summary_line_and_commands_that_work_when_pasted(tmp_path):
    import shlex

    run = "outputs/runs/my run"  # a space: the printed commands quote it
    result = run_cli("env=InvertedPendulum-v4", *TINY, f"hydra.run.dir={run}", cwd=tmp_path)
    assert result.returncode == 0, result.stderr[-2000:]
    done, header, evaluate, report, resume = result.stderr.splitlines()[-5:]
    assert done.startswith("done: InvertedPendulum-v4, 512 frames in ") and done.endswith(f"; files in {run}")
    assert "; final eval " in done and ", best " in done
    assert header == "next: watch the best checkpoint, plot the run, train it on to 1,024 frames:"
    python = sys.executable
    assert shlex.split(evaluate) == [python, "-m", "ppo_torchrl.evaluate", f"run={run}", "video=true"]
    assert shlex.split(resume) == [python, "-m", "ppo_torchrl", f"resume={run}", "collector.total_frames=1024"]
    pasted = subprocess.run(report, shell=True, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert pasted.returncode == 0, pasted.stderr[-2000:]
    from PIL import Image

    assert Image.open(tmp_path / run / "report.png").mode == "P"  # 256 colours: a plot's bytes kept small (report.py)
    assert not (tmp_path / run / "__main__.log").exists()  # no empty log file in the run dir

    # run=latest: the newest run dir under ./outputs, said on stderr
    export = run_cli("run=latest/InvertedPendulum-v4", module="ppo_torchrl.export", cwd=tmp_path)
    assert export.returncode == 0, export.stderr[-2000:]
    assert export.stderr.startswith(f"latest/InvertedPendulum-v4: {run} (InvertedPendulum-v4, finished at 512 frames)")
    assert (tmp_path / run / "policy.pt").is_file()


def fake_run(path, env, age_s):
    import os
    import time

    path.mkdir(parents=True)
    (path / ".ppo_torchrl.json").write_text("{}")
    (path / "summary.json").write_text(json.dumps({"env": env, "status": "finished", "frames": 2048}))
    os.utime(path / "summary.json", (time.time() - age_s,) * 2)
    return path


def test_latest_is_the_newest_run_dir_under_outputs(tmp_path, monkeypatch, capsys):
    from pathlib import Path

    from ppo_torchrl.cli import resolve_run
    from ppo_torchrl.errors import ConfigError

    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match="latest: no run dir under outputs/"):
        resolve_run("latest")
    hopper = fake_run(Path("outputs/runs/d/10-00-00_Hopper-v4_seed1"), "Hopper-v4", 300)
    step = fake_run(Path("outputs/multirun/d/t/0_seed=1"), "mjcf:quadruped_step.xml", 200)
    fake_run(Path("outputs/runs/d/not_ours"), "Hopper-v4", 0).joinpath(".ppo_torchrl.json").unlink()
    assert resolve_run("latest") == step
    assert capsys.readouterr().err == f"latest: {step} (mjcf:quadruped_step.xml, finished at 2,048 frames)\n"
    assert resolve_run("latest/Hopper-v4") == hopper
    assert resolve_run("latest/quadruped_step") == resolve_run("latest/mjcf:quadruped_step.xml") == step
    with pytest.raises(ConfigError, match="no run of Walker2d-v4 under outputs/ .*; its runs are of Hopper-v4, "
                                          "mjcf:quadruped_step.xml"):
        resolve_run("latest/Walker2d-v4")
    assert resolve_run("some/dir") == Path("some/dir")


def test_latest_skips_runs_in_use_failed_and_damaged_and_prefers_finished_ones(tmp_path, monkeypatch, capsys):
    """Issue 47: run=latest picks the newest run that can be used; a damaged summary.json is a warning line."""
    import fcntl
    import os
    from pathlib import Path

    from ppo_torchrl.cli import resolve_run

    monkeypatch.chdir(tmp_path)
    finished = fake_run(Path("outputs/runs/d/a_finished"), "Hopper-v4", 400)
    killed = fake_run(Path("outputs/runs/d/b_killed"), "Hopper-v4", 300)  # kill -9: 'running', no lock held
    (killed / "summary.json").write_text(json.dumps({"env": "Hopper-v4", "status": "running", "frames": 10}))
    failed = fake_run(Path("outputs/runs/d/c_failed"), "Hopper-v4", 200)
    (failed / "summary.json").write_text(json.dumps({"env": "Hopper-v4", "status": "failed", "frames": 10}))
    training = fake_run(Path("outputs/runs/d/d_training"), "Hopper-v4", 100)
    fd = os.open(training, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # another process's run, still training
    try:
        damaged = fake_run(Path("outputs/runs/d/e_damaged"), "Hopper-v4", 0)
        (damaged / "summary.json").write_text("[1, 2")
        listed = fake_run(Path("outputs/runs/d/f_list"), "Hopper-v4", 0)
        (listed / "summary.json").write_text("[1, 2]")
        assert resolve_run("latest") == finished
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 3 and sum(line.startswith("warning: latest: skipped ") for line in err) == 2
        (finished / "summary.json").unlink()
        assert resolve_run("latest") == killed  # no finished run left: the killed one can still be resumed
    finally:
        os.close(fd)


@pytest.mark.parametrize("overrides, name", [
    (["env=Hopper-v4"], "Hopper-v4"),
    (["env=quadruped_step"], "quadruped_step"),  # not mjcf
    (["experiment=aidl_anymal"], "aidl_anymal"),
    (["env=gym", "env.id=Swimmer-v4"], "Swimmer-v4"),
    (["env=mjcf", "env.xml_file=quadruped_a1like.xml"], "quadruped_a1like"),
])
def test_run_dirs_are_named_by_the_preset_or_env_file(overrides, name):
    from ppo_torchrl.compose import compose, hydra_value

    run_dir = hydra_value(compose([*overrides, "seed=4"], with_hydra=True), "hydra.run.dir")
    assert run_dir.startswith("outputs/runs/") and run_dir.endswith(f"_{name}_seed4")


@pytest.mark.parametrize("overrides, shown, hidden", [
    (["env=Hopper-v4", "loss=kl_ppo"], ["loss.kl_target"], ["env.locomotion", "env.terrain", "loss.clip_epsilon"]),
    (["env=quadruped_step"], ["env.locomotion", "env.terrain", "loss.clip_epsilon"], ["loss.kl_beta"]),
    (["env=Hopper-v4", "loss=reinforce", "advantage=mc"], ["loss.critic_loss"],
     ["loss.entropy_coef", "loss.critic_coef", "advantage.lmbda"]),
])
def test_cfg_job_shows_only_what_the_env_and_loss_read(overrides, shown, hidden, capsys):
    from omegaconf import OmegaConf

    from ppo_torchrl.__main__ import prepare

    with pytest.raises(SystemExit) as exit_:
        prepare([*overrides, "--cfg", "job"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    first, cfg = out.splitlines()[0], OmegaConf.create(out)
    assert first.startswith("# left out, as this env, loss and advantage do not read them: ")
    for key in shown:
        assert OmegaConf.select(cfg, key) is not None, key
    for key in hidden:
        assert OmegaConf.select(cfg, key) is None and key in first, key


def test_sweep_plot_legend_shows_only_what_varies(tmp_path, monkeypatch):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ppo_torchrl import report

    for num, (loss, seed) in enumerate([("clip_ppo", 1), ("kl_ppo", 1), ("kl_ppo", 2)]):
        job = tmp_path / f"{num}_loss={loss},seed={seed}"
        (job / ".hydra").mkdir(parents=True)
        (job / ".hydra" / "overrides.yaml").write_text(
            f"- env=InvertedPendulum-v4\n- collector.total_frames=512\n- loss={loss}\n- seed={seed}\n")
        (job / "summary.json").write_text(json.dumps({"env": "InvertedPendulum-v4", "seed": seed, "status": "finished",
                                                      "frames": 512, "train_return_last100": 9.0 + seed,
                                                      "eval_return_mean": 20.0, "sps": 300.0}))
        (job / "metrics.csv").write_text("frames,train/return_last100\n256,5.0\n512,9.0\n")
    figures, close = [], plt.close
    monkeypatch.setattr(plt, "close", figures.append)  # keep the figure to read it
    report.plot_sweep(tmp_path)
    ax = figures[0].axes[0]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["loss=clip_ppo (n=1)", "loss=kl_ppo (n=2)"]
    assert ax.get_title() == ("InvertedPendulum-v4: train return, mean and 95% CI over seeds\n"
                              "every run: collector.total_frames=512 env=InvertedPendulum-v4")
    close(figures[0])
