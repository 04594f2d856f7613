"""Bad input and run-dir ownership: each refused command exits with its code and one line, and no
file of an existing run changes (the reliability round 2 issue)."""

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ppo_torchrl.run import checkpoint
from ppo_torchrl.__main__ import prepare
from ppo_torchrl.run.checkpoint import CheckpointManager
from ppo_torchrl.run.lifecycle import resume_config
from ppo_torchrl.errors import Interrupted, TrainingError, guarded
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, TINY, App, run_cli

MOTOR_WITHOUT_CTRLRANGE = """<mujoco><worldbody><body name="base" pos="0 0 0.5"><freejoint/>
<geom type="sphere" size="0.1"/><body name="leg"><joint name="hip" type="hinge"/>
<geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02"/></body></body></worldbody>
<actuator><motor joint="hip" gear="10" {limits}/></actuator></mujoco>"""

# (command, exit code, a part of the one `error:` line)
BAD_INPUT = [
    (["eval.video_episodes=[5]"], 2, "eval.video_episodes=[5] must name episodes in 0..4"),
    (["eval.video_length=-1"], 2, "eval.video_length=-1.0 must be > 0 seconds"),
    (["env=Hoper-v4"], 2, "did you mean env=Hopper-v4?"),
    (["env=gym", "env.id=NoSuchEnv-v0"], 2, "NoSuchEnv-v0"),
    (["env=gym"], 2, "env.id must be given"),
    (["loss=trpo"], 2, "Available options in 'loss': a2c, clip_ppo"),
    (["loss.clip_eps=0.1"], 2, "Key 'clip_eps' not in 'LossConfig'"),
    (["seed=notanint"], 2, "could not be converted to Integer"),
    (["seed=-1"], 2, "seed=-1 must be in [0, 2^32)"),
    (["seed=4294967296"], 2, "must be in [0, 2^32)"),
    (["env.max_episode_steps=0"], 2, "env.max_episode_steps=0 must be > 0"),
    (["env.transforms.obs_clip=-1"], 2, "env.transforms.obs_clip=-1.0 must be > 0"),
    (["env.transforms.reward_clip=-1"], 2, "env.transforms.reward_clip=-1.0 must be > 0"),
    (["env.transforms.reward_scale=0"], 2, "env.transforms.reward_scale=0.0 must be > 0"),
    (["loss.clip_epsilon=1"], 2, "loss.clip_epsilon=1.0 must be in (0, 1)"),
    (["loss.clip_epsilon=0"], 2, "loss.clip_epsilon=0.0 must be in (0, 1)"),
    (["optim.lr=-1"], 2, "optim.lr=-1.0 must be > 0"),
    (["collector.frames_per_batch=1000"], 2, "not divisible into minibatches"),
    (["collector.total_frames=100"], 2, "must be >= collector.frames_per_batch"),
    (["collector.num_envs=0"], 2, "collector.num_envs=0 must be >= 1"),
    (["loss.minibatch_size=0"], 2, "loss.minibatch_size=0 must be >= 1"),
    (["collector.backend=nope"], 2, "collector.backend='nope' is not known"),
    (["policy.head=beta"], 2, "policy.head='beta' is not allowed"),
    (["device=tpu"], 2, "device='tpu' is not allowed"),
    (["env=quadruped", "env.locomotion.main_body=nobody"], 2, "main_body=nobody is not a body of quadruped.xml"),
    (["resume=/nonexistent/run"], 2, "no such directory"),
    (["resume=" + str(ROOT / "conf")], 2, "not a ppo_torchrl run dir"),
    (["-m", "seed=1,2", "loss=trpo,clip_ppo"], 2, "Could not find 'loss/trpo'"),
    (["-m", "seed=1,-1"], 2, "seed=-1 must be in [0, 2^32)"),
    (["--cfg", "job", "seed=abc"], 2, "could not be converted to Integer"),
    (["hydra.run.dir=" + str(ROOT / "README.md")], 2, "is a file"),
    (["hydra.run.dir=" + str(ROOT / "conf")], 2, "is not empty and is not a ppo_torchrl run dir"),
]


def refused(args, capsys):
    """Run the entry point's checks in-process: (exit code, stderr lines)."""
    with pytest.raises(SystemExit) as exit_:
        guarded(prepare, args)
    return exit_.value.code, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


@pytest.mark.parametrize("args, code, expected", BAD_INPUT, ids=[" ".join(a) for a, _, _ in BAD_INPUT])
def test_bad_input_is_one_error_line_and_its_exit_code(args, code, expected, capsys, tmp_path):
    if not any(a.startswith(("env=", "resume=")) for a in args):
        args = ["env=InvertedPendulum-v4", *args]
    if not any(a.startswith(("-m", "resume=", "hydra.run.dir=")) for a in args):
        args.append(f"hydra.run.dir={tmp_path / 'new'}")
    got, lines = refused(args, capsys)
    assert got == code and len(lines) == 1, lines
    assert lines[0].startswith("error: ") and expected in lines[0]
    assert not (tmp_path / "new").exists()  # nothing written


def test_a_missing_gymnasium_extra_is_one_line(capsys, tmp_path):
    try:
        import Box2D  # noqa: F401
        pytest.skip("Box2D is installed here")
    except ImportError:
        pass
    code, lines = refused(["env=gym", "env.id=BipedalWalker-v3", f"hydra.run.dir={tmp_path}/r"], capsys)
    assert code == 2 and len(lines) == 1 and "Box2D is not installed" in lines[0]


def test_mjcf_motor_without_ctrlrange_takes_its_forcerange_or_is_refused(capsys, tmp_path):
    from ppo_torchrl.envs.make import env_spec

    from conftest import compose_config

    refused_xml, forced_xml = tmp_path / "no_limits.xml", tmp_path / "force.xml"
    refused_xml.write_text(MOTOR_WITHOUT_CTRLRANGE.format(limits=""))
    forced_xml.write_text(MOTOR_WITHOUT_CTRLRANGE.format(limits='forcerange="-5 5"'))
    code, lines = refused(["env=mjcf", f"env.xml_file={refused_xml}", f"hydra.run.dir={tmp_path}/r"], capsys)
    assert code == 2 and len(lines) == 1 and "has no ctrlrange" in lines[0]
    spec = env_spec(compose_config(["env=mjcf", f"env.xml_file={forced_xml}", "env.locomotion.main_body=base"]).env)
    assert spec.action_low.tolist() == [-0.5] and spec.action_high.tolist() == [0.5]  # forcerange / gear


def tree_digest(directory):
    return {str(p.relative_to(directory)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(directory.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def finished_run(cli_finished_run, tmp_path_factory):
    """A real finished run (4 iterations, checkpoints every iteration), via the CLI: this module's own copy of the
    test worker's one (conftest.cli_finished_run), so no module sees what another did to its copy."""
    import shutil

    return Path(shutil.copytree(cli_finished_run, tmp_path_factory.mktemp("finished") / "run", symlinks=True))


@pytest.mark.parametrize("extra", [[], ["collector.total_frames=512"], ["optim.lr=-1"]])
def test_a_new_run_never_touches_an_existing_run(finished_run, extra, capsys):
    before = tree_digest(finished_run)
    code, lines = refused(["env=InvertedPendulum-v4", *TINY, f"hydra.run.dir={finished_run}", *extra], capsys)
    assert code == 2 and len(lines) == 1
    assert "already holds a run" in lines[0] or "optim.lr" in lines[0]
    assert tree_digest(finished_run) == before


def test_overwrite_replaces_the_old_run_whole(finished_run, tmp_path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(finished_run, run)
    result = run_cli("env=InvertedPendulum-v4", *TINY, "overwrite=true", f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-2000:]
    names = sorted(p.name for p in (run / "checkpoints").iterdir())
    assert names == ["best.pt", "frames_0000000256.pt", "frames_0000000512.pt", "last.pt"]  # none of 768, 1024
    assert checkpoint.load(run / "checkpoints" / "best.pt")["frames"] <= 512
    assert json.loads((run / "summary.json").read_text())["frames"] == 512


def test_a_second_process_is_refused_while_the_first_writes(tmp_path):
    run = tmp_path / "run"
    args = ["env=InvertedPendulum-v4", "collector.total_frames=1000000", "collector.frames_per_batch=256",
            "eval.every_frames=0", "logger=none", "compile=false"]
    first = App([*args, f"hydra.run.dir={run}"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.time() + 60
        while time.time() < deadline and not (run / "metrics.csv").exists():
            time.sleep(0.2)
        second = run_cli(*args, "overwrite=true", f"hydra.run.dir={run}", timeout=60)
        assert second.returncode == 2 and second.stderr.strip().count("\n") == 0
        assert f"is in use by pid {first.pid}" in second.stderr
    finally:
        first.send_signal(signal.SIGINT)
        first.communicate(timeout=60)
    assert first.returncode == 130 and (run / "checkpoints" / "last.pt").is_file()


def test_a_failed_resume_leaves_the_config_as_it_was(tiny_cfg, tmp_path):
    Trainer(tiny_cfg(), tmp_path).train()
    config = (tmp_path / "config.yaml").read_text()
    cfg = resume_config(tmp_path, ["optim.lr=1e6", "optim.max_grad_norm=null", "collector.total_frames=2048"],
                        checkpoint.load(tmp_path / "checkpoints" / "last.pt"))
    with pytest.raises(TrainingError):
        Trainer(cfg, tmp_path, resume=checkpoint.load(tmp_path / "checkpoints" / "last.pt")).train()
    assert (tmp_path / "config.yaml").read_text() == config


def test_resuming_with_no_frames_left_is_refused(finished_run, capsys):
    code, lines = refused([f"resume={finished_run}", "collector.total_frames=512"], capsys)
    assert code == 2 and "has done 1024 frames already" in lines[0]


@pytest.mark.parametrize("signum, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_second_signal_before_any_checkpoint_says_nothing_was_saved(tiny_cfg, tmp_path, signum, code):
    trainer = Trainer(tiny_cfg("checkpoint.every_frames=0", "collector.total_frames=2048"), tmp_path)
    collect = trainer.collector.collect

    def collect_then_two_signals():
        batch = collect()
        if trainer.iteration == 1:
            os.kill(os.getpid(), signum)
            os.kill(os.getpid(), signum)
        return batch

    trainer.collector.collect = collect_then_two_signals
    with pytest.raises(Interrupted, match="nothing was saved: the run had done 256 frames") as error:
        trainer.train()
    from ppo_torchrl.errors import exit_code

    assert exit_code(error.value) == code and not (tmp_path / "checkpoints" / "last.pt").exists()


def test_checkpoints_are_pruned_by_frame_count(tmp_path):
    manager = CheckpointManager(tmp_path, keep_last=2, save_best=False)
    for frames in (100, 900, 20_000):  # 900 sorts after 20000 by name; 20000 lies beyond this run's present
        checkpoint.save(tmp_path / f"frames_{frames:d}.pt", {"actor": {}, "frames": frames})
    manager.save({"actor": {}, "frames": 1000})
    assert sorted(p.name for p in tmp_path.glob("frames_*.pt")) == ["frames_0000001000.pt", "frames_900.pt"]


def test_a_sweep_dir_that_holds_runs_is_refused(finished_run, tmp_path, capsys):
    import shutil

    sweep = tmp_path / "sweep"
    shutil.copytree(finished_run, sweep / "0_InvertedPendulum-v4_seed1")
    before = tree_digest(sweep)
    code, lines = refused(["-m", "env=InvertedPendulum-v4", *TINY, "seed=1,2", f"hydra.sweep.dir={sweep}"], capsys)
    assert code == 2 and len(lines) == 1 and "already holds a sweep" in lines[0] and "overwrite=true" in lines[0]
    assert tree_digest(sweep) == before


@pytest.mark.parametrize("debug", [False, True])
def test_an_internal_error_is_one_line_exit_1_and_its_traceback_in_the_run_dir(tmp_path, capsys, monkeypatch, debug):
    from ppo_torchrl.run.signals import ON_DISK

    if debug:
        monkeypatch.setenv("PPO_TORCHRL_DEBUG", "1")
    monkeypatch.setattr(ON_DISK, "run_dir", tmp_path)
    monkeypatch.setattr(ON_DISK, "started", True)  # the run is kept: its error.log with it

    def buggy():
        raise KeyError("a bug")

    with pytest.raises(SystemExit) as exit_:
        guarded(buggy)
    err = capsys.readouterr().err
    assert exit_.value.code == 1
    assert err.strip().splitlines()[-1].startswith("error: internal error (KeyError: 'a bug'); please report it")
    assert ("Traceback" in err) == debug  # the traceback on screen only with PPO_TORCHRL_DEBUG=1
    assert "raise KeyError" in (tmp_path / "error.log").read_text()
