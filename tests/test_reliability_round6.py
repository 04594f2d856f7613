"""Reliability round 6 (issue 76 item 2): records, the Python API answering as the CLI does, robot options that mean
nothing, the benchmark scripts' one-line errors, odd paths and the report's text columns. Each case is a test that
fails on the code before round 6; a refused command leaves every file as it was."""

from __future__ import annotations

import errno
import json
import lzma
import os
import resource
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import ppo_torchrl
from ppo_torchrl import evaluate, report
from ppo_torchrl.run import checkpoint
from ppo_torchrl import records
from ppo_torchrl.__main__ import prepare
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.lifecycle import Lifecycle
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, TINY, compose_config, ran
from test_bad_input import refused, tree_digest
from test_reliability_round3 import RUN

sys.path.insert(0, str(ROOT / "benchmarks"))
import cli_args  # noqa: E402
import gait_check  # noqa: E402
import robots_table  # noqa: E402
import whole_run  # noqa: E402

GO1 = ROOT / "results" / "robots" / "legged_v2_2026-11-28" / "go1_seed12"  # a shipped legged run (record checkpoint)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A real finished TINY run (2 batches of 256 frames, a checkpoint each), trained in-process."""
    run = tmp_path_factory.mktemp("finished") / "run"
    Trainer(compose_config(RUN), run).train()
    return run


@pytest.fixture
def run_copy(finished_run, tmp_path):
    return Path(shutil.copytree(finished_run, tmp_path / "run"))


def one_line(code, lines, expected, exit_code=2):
    assert code == exit_code and len(lines) == 1 and lines[0].startswith("error: "), lines
    assert expected in lines[0], lines


# ---------------------------------------------------------------- records

def test_records_writes_its_temp_file_under_a_name_of_its_own(tmp_path):
    """records: it wrote a fixed temp name, FILE.xz.tmp, and renamed it over FILE.xz: a user's file of that name was
    replaced (gone). Now a temp name of its own (mkstemp in the same dir); the user's file stays, nothing else left."""
    plain = tmp_path / "metrics.csv"
    plain.write_text("iteration,frames\n1,2048\n2,4096\n")
    users = tmp_path / "metrics.csv.xz.tmp"
    users.write_text("the user's own file")
    assert records.main([str(plain)]) == 0
    assert users.read_text() == "the user's own file"
    assert lzma.decompress((tmp_path / "metrics.csv.xz").read_bytes()) == plain.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.csv", "metrics.csv.xz", "metrics.csv.xz.tmp"]


def test_records_refuses_a_run_that_is_training(run_copy, capsys):
    """records on a training run's last.pt made a record checkpoint under the running run (after a kill -9 that run
    could no longer be resumed), and compressed its growing log: it took no lock. Now it takes the run's lock,
    exclusive: a run training there (which holds it) refuses the command in one line naming its pid, nothing written."""
    life = Lifecycle()
    life.lock(run_copy)  # what a run training there holds (Lifecycle.claim)
    before = tree_digest(run_copy)
    try:
        code, lines = ran(records.main, [str(run_copy / "metrics.csv"), str(run_copy / "checkpoints" / "last.pt")],
                          capsys)
    finally:
        life.finish()
    one_line(code, lines, f"is in use by pid {os.getpid()}")
    assert tree_digest(run_copy) == before
    assert records.main([str(run_copy / "checkpoints" / "last.pt")]) == 0  # the run has ended: it is made


@pytest.mark.parametrize("kind", ["metrics.csv", "checkpoints/last.pt"])
def test_records_at_a_file_size_limit_is_one_line_and_leaves_no_temp_file(run_copy, kind):
    """records under a file-size limit (ulimit -f; EFBIG): a raw `error: [Errno 27] File too large` and, for a log,
    its temp file left. Now the app's one line naming the file and the fix, exit 1, no temp file, nothing replaced."""
    target = run_copy / kind
    if kind == "metrics.csv":  # a log whose record is far over the limit
        rows = np.random.default_rng(0).normal(size=(2000, 4))
        target.write_text("a,b,c,d\n" + "\n".join(",".join(f"{x:.9f}" for x in row) for row in rows) + "\n")
    before = tree_digest(run_copy)

    def limit():
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    result = subprocess.run([sys.executable, "-m", "ppo_torchrl.records", str(target)], capture_output=True, text=True,
                            cwd=ROOT, timeout=300, preexec_fn=limit, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 1 and len(lines) == 1, result.stderr[-2000:]
    assert lines[0].startswith("error: a file reached the file size limit writing ") and "ulimit -f" in lines[0]
    assert tree_digest(run_copy) == before and not [p for p in run_copy.rglob("*") if p.name.endswith(".tmp")]


# ---------------------------------------------------------------- the Python API answers as the CLI does

def test_the_api_refuses_booleans_given_as_strings(run_copy, tmp_path):
    """train(overwrite="false") took the string as true (and replaced the run); evaluate_run(deterministic="false")
    ran deterministic episodes. A bool is True or False: anything else is ConfigError, nothing written."""
    before = tree_digest(run_copy)
    with pytest.raises(ConfigError, match=r"overwrite='false' must be True or False"):
        ppo_torchrl.train(RUN, run_dir=run_copy, overwrite="false")
    with pytest.raises(ConfigError, match=r"deterministic='false' must be True or False"):
        ppo_torchrl.evaluate_run(run_copy, episodes=1, checkpoint="last", deterministic="false")
    assert tree_digest(run_copy) == before and not list(tmp_path.glob("run.replaced-*"))


def test_the_api_refuses_an_empty_run_dir(tmp_path, monkeypatch):
    """train(run_dir="") trained in the working dir (Path("") is "."); the CLI refuses hydra.run.dir= empty."""
    (tmp_path / "cwd").mkdir()
    monkeypatch.chdir(tmp_path / "cwd")
    with pytest.raises(ConfigError, match="run_dir='': the value is empty"):
        ppo_torchrl.train(RUN, run_dir="")
    assert list((tmp_path / "cwd").iterdir()) == []


def test_the_api_refuses_resume_with_run_dir_in_one_message(run_copy, tmp_path):
    """train(resume=<run>, run_dir=<new>) ignored run_dir without a word and resumed in place."""
    before = tree_digest(run_copy)
    with pytest.raises(ConfigError) as error:
        ppo_torchrl.train(["collector.total_frames=768"], resume=run_copy, run_dir=tmp_path / "new")
    assert "continues that run in its own dir" in str(error.value) and "not both" in str(error.value)
    assert tree_digest(run_copy) == before and not (tmp_path / "new").exists()


@pytest.mark.parametrize("kwargs, expected", [
    ({"episodes": 2.5}, "episodes=2.5 must be a whole number"),  # was rounded to 2
    ({"episodes": True}, "episodes=True must be a whole number (an int), not bool"),  # was one episode
    ({"episodes": float("inf")}, "episodes=inf must be a whole number"),
    ({"episodes": 10**12}, "episodes=1000000000000 must be at most 1,000,000"),  # exhausted memory
    ({"seed": -1}, "seed=-1 must be in 0..4294967"),  # odd paths: numpy's 'Seed must be greater or equal to zero'
])
def test_the_api_refuses_episode_counts_and_seeds_the_cli_refuses(run_copy, kwargs, expected):
    """evaluate_run() rounded a non-integer count, took an unbounded one (memory exhausted) and seed=-1 raised
    numpy's error: the CLI's own check (cli.check_episodes) now runs on every call."""
    with pytest.raises(ConfigError) as error:
        ppo_torchrl.evaluate_run(run_copy, checkpoint="last", **{"episodes": 1, **kwargs})
    assert f"evaluate_run(): {expected}" in str(error.value), str(error.value)


@pytest.mark.parametrize("override, expected", [
    ("++resume={run}", "give resume, run_dir and overwrite as arguments"),  # resumed nothing, trained a new run
    ("++overwrite=true", "give resume, run_dir and overwrite as arguments"),  # ignored
    ("++hydra.run.dir={new2}", "give resume, run_dir and overwrite as arguments"),
    ("env=Hoper-v4", "did you mean env=Hopper-v4?"),  # the CLI's did-you-mean (Hydra's list of every file before)
    ("--env", "not --key value"),
])
def test_the_api_checks_every_override_as_the_cli_does(run_copy, tmp_path, override, expected):
    """`++`-prefixed overrides passed the API's check (++resume=, ++overwrite=); env= had no did-you-mean; a flag
    went to Hydra. The API runs the CLI's override checks (overrides.checked_overrides), nothing written."""
    before = tree_digest(run_copy)
    arg = override.format(run=run_copy, new2=tmp_path / "new2")
    with pytest.raises(ConfigError) as error:
        ppo_torchrl.train([*RUN, arg], run_dir=tmp_path / "new")
    assert expected in str(error.value), str(error.value)
    assert tree_digest(run_copy) == before and not (tmp_path / "new").exists() and not (tmp_path / "new2").exists()


@pytest.mark.parametrize("observation, expected", [
    (np.zeros(1), "an observation of shape [1] for a policy of observations of size 4"),  # was broadcast
    (np.zeros((3, 5)), "an observation of shape [3, 5]"),
    (np.array([0.0, np.nan, 0.0, 0.0]), "the observation holds nan at [1]"),  # NaN actions came back
    (np.array([0.0, 0.0, np.inf, 0.0]), "the observation holds inf at [2]"),
    (["a", "b", "c", "d"], "the observation (list) is not an array of numbers"),
])
def test_predict_checks_the_shape_and_finiteness_of_an_observation(run_copy, observation, expected):
    policy = ppo_torchrl.load(run_copy, checkpoint="last")
    with pytest.raises(ValueError) as error:  # ConfigError is a ValueError
        policy.predict(observation)
    assert isinstance(error.value, ConfigError) and f"predict(): {expected}" in str(error.value), str(error.value)
    assert policy.predict(np.zeros((2, 4))).shape == (2, 1)  # a good batch still answers


def test_ctrl_c_inside_train_reaches_the_caller_as_keyboard_interrupt(tmp_path, monkeypatch):
    """A Ctrl-C in train()'s loop reached the caller as Interrupted, an Exception, so `except Exception` loops over
    seeds went on. Now KeyboardInterrupt, with the checkpoint saved as before (the iteration finished, then saved)."""
    save = checkpoint.CheckpointManager.save

    def save_then_ctrl_c(self, state, eval_return=None):  # the user's Ctrl-C, just after the first checkpoint
        path = save(self, state, eval_return)
        if state["frames"] == 256:
            os.kill(os.getpid(), signal.SIGINT)
        return path

    monkeypatch.setattr(checkpoint.CheckpointManager, "save", save_then_ctrl_c)
    run_dir = tmp_path / "run"
    caught = None
    try:
        ppo_torchrl.train(["env=InvertedPendulum-v4", *TINY, "collector.total_frames=2048"], run_dir=run_dir)
    except Exception as error:  # noqa: BLE001 - what a loop over seeds catches
        pytest.fail(f"a Ctrl-C reached the caller as an Exception: {type(error).__name__}: {error}")
    except KeyboardInterrupt as stop:
        caught = stop
    assert caught is not None and "checkpoint at frame 256 saved" in str(caught), caught
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["status"] == "interrupted" and checkpoint.load(run_dir / "checkpoints" / "last.pt")["frames"] == 256


# ---------------------------------------------------------------- values that mean nothing

@pytest.mark.parametrize("key", ["friction_scale", "trunk_mass_scale"])
@pytest.mark.parametrize("value", ["inf", "1e9", "0", "-1"])
def test_robot_evaluation_options_that_mean_nothing_are_one_line_naming_the_key_typed(key, value):
    """evaluate's env.legged.friction_scale / trunk_mass_scale at inf or 1e9 ran and wrote an eval.json of NaN; at 0
    or -1 the line named env.locomotion.<key>, which the user did not type. Checked as training checks (finite, in
    (0, 10]), on the shipped Go1 run's saved config."""
    from ppo_torchrl.config import run_config
    from ppo_torchrl.evaluate import apply_overrides

    cfg = run_config(GO1, checkpoint.load(GO1 / "checkpoints" / "last.pt"))
    with pytest.raises(ConfigError) as error:
        apply_overrides(cfg, [f"env.legged.{key}={value}"])
    assert str(error.value).startswith(f"env.legged.{key}=") and "env.locomotion" not in str(error.value), error.value


def test_evaluate_with_a_grip_of_1e9_writes_nothing(tmp_path, capsys):
    """The command itself: one line, exit 2, no eval.json (it wrote one of NaN returns)."""
    code, lines = ran(evaluate.main, [f"run={GO1}", "checkpoint=last", "episodes=1",
                                                  "env.legged.friction_scale=1e9", f"out={tmp_path / 'eval'}"], capsys)
    one_line(code, lines, "env.legged.friction_scale=1000000000.0 must be > 0 and at most 10")
    assert not (tmp_path / "eval").exists()


def test_env_legged_without_its_model_names_env_xml_file_not_curriculum_keys(tmp_path, capsys):
    """`env=legged` alone said `env.terrain.curriculum=true needs env.terrain.step_height_range=[min, max]`: keys the
    recipe derives from the robot, never typed. Now it names env.xml_file and the six shipped robots."""
    code, lines = refused(["env=legged", f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    one_line(code, lines, "env=legged reads its robot from a model file: give env.xml_file=")
    assert "curriculum" not in lines[0] and lines[0].count("menagerie/") >= 6, lines
    assert not (tmp_path / "new").exists()


# ---------------------------------------------------------------- the benchmark scripts' one-line errors

BENCH = {
    "gait_check missing dir": (gait_check, ["{tmp}/nowhere"], "no such directory"),
    "gait_check a run of another kind": (gait_check, ["{run}"], "not of env=legged"),
    "gait_check --episodes 0": (gait_check, [str(GO1), "--episodes", "0"], "must be >= 1, not 0"),
    "gait_check --episodes -1": (gait_check, [str(GO1), "--episodes", "-1"], "must be >= 1, not -1"),
    "gait_check a dir as --out": (gait_check, [str(GO1), "--out", "{tmp}"], "is a directory"),
    "robots_table missing dir": (robots_table, ["{tmp}/nowhere"], "no such run dir"),
    "robots_table a run of another kind": (robots_table, ["{run}"], "not of env=legged"),
    "robots_table a sweep dir without a sweep": (robots_table, [f"{GO1}:{{tmp}}"], "holds no height sweep"),
    "robots_table --goal go1": (robots_table, [str(GO1), "--goal", "go1"], "expected <robot>=<share"),
    "robots_table --goal go1=abc": (robots_table, [str(GO1), "--goal", "go1=abc"], "expected <robot>=<share"),
    "robots_table a dir as --out": (robots_table, [str(GO1), "--out", "{tmp}"], "is a directory"),
    "whole_run --frames 0": (whole_run, ["--frames", "0"], "must be >= 1, not 0"),
    "whole_run --frames -5": (whole_run, ["--frames", "-5"], "must be >= 1, not -5"),
    "whole_run a file as --out": (whole_run, ["--out", "{tmp}/file"], "is a file"),
    "whole_run --backends nope": (whole_run, ["--backends", "nope"], "takes fast, envpool"),
    "whole_run --sb3-vec nope": (whole_run, ["--sb3-vec", "nope"], "takes dummy, subproc"),
    "whole_run --num-envs 3": (whole_run, ["--num-envs", "3"], "does not divide the 2048 frames"),
}


@pytest.mark.parametrize("case", list(BENCH))
def test_the_benchmark_scripts_refuse_bad_input_in_one_line(case, run_copy, tmp_path, capsys):
    """gait_check.py, robots_table.py and whole_run.py on missing dirs, runs of the wrong kind, counts of 0 or below,
    a directory as --out and malformed --goal values: tracebacks (or argparse's two lines). Now one `error:` line,
    exit 2, nothing written."""
    module, argv, expected = BENCH[case]
    (tmp_path / "file").write_text("the user's")
    argv = [a.format(tmp=tmp_path, run=run_copy) for a in argv]
    before, outputs = tree_digest(tmp_path), ROOT / "results" / "speed" / "whole_run"
    existed = outputs.exists()
    try:
        code = cli_args.run(module.main, argv)  # the scripts' entry point: `sys.exit(run(main))`
    except SystemExit as exit_:
        code = exit_.code
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    one_line(code, lines, expected)
    assert tree_digest(tmp_path) == before and outputs.exists() == existed


def test_the_benchmark_scripts_ran_through_their_error_path(run_copy, capsys):
    """The same through the scripts' own entry point (`python benchmarks/gait_check.py ...`: cli_args.run), once."""
    result = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "gait_check.py"), str(run_copy)],
                            capture_output=True, text=True, cwd=ROOT, timeout=300)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1 and "not of env=legged" in lines[0], result.stderr[-1500:]


# ---------------------------------------------------------------- odd paths

@pytest.fixture(scope="module")
def odd_model(tmp_path_factory):
    """An in-house model at a path with a space and a non-ASCII letter."""
    folder = tmp_path_factory.mktemp("models") / "my robots" / "ünitree"
    folder.mkdir(parents=True)
    return Path(shutil.copy(ROOT / "ppo_torchrl" / "assets" / "quadruped.xml", folder / "quadruped.xml"))


def test_a_model_path_with_a_space_or_a_non_ascii_letter_reaches_the_app_as_typed(odd_model, tmp_path):
    """env.xml_file=<path with a space or a non-ASCII letter> through the CLI's override handling: Hydra's
    `LexerNoViableAltException` line (quoted for Hydra it passed). Now the path is handed over as typed, whatever its
    characters, written plain or quoted."""
    from ppo_torchrl.compose import compose

    for value in (str(odd_model), f"'{odd_model}'", f'"{odd_model}"'):
        argv = prepare(["env=quadruped", f"env.xml_file={value}", *TINY, f"hydra.run.dir={tmp_path / 'new'}"])
        assert compose([a for a in argv if not a.startswith("hydra.")]).env.xml_file == str(odd_model), value
    assert not (tmp_path / "new").exists()  # checked, nothing claimed


def test_a_resume_with_such_a_model_path_is_not_an_internal_error(odd_model, tmp_path):
    """resume=<run> env.xml_file=<path with a space>: the check passed, then Hydra's own parse of the command line
    failed (OverrideParseException): an internal error, exit 1. Now the argv Hydra gets parses, the path as typed."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    run = tmp_path / "run"
    Trainer(compose_config(["env=quadruped", *TINY, f"env.xml_file='{odd_model}'"]), run).train()
    argv = prepare([f"resume={run}", "collector.total_frames=768", f"env.xml_file={odd_model}"])
    parsed = OverridesParser.create().parse_overrides([a for a in argv if not a.startswith("-")])  # as hydra.main does
    model = next(o for o in parsed if o.key_or_group == "env.xml_file")
    assert os.environ[model.value().removeprefix("${oc.env:").removesuffix("}")] == str(odd_model)


def test_a_run_dir_through_a_symlink_loop_is_one_line(tmp_path, capsys, run_copy):
    """hydra.run.dir (CLI), run_dir= (API) and evaluate's out= through a loop of symlinks (`ln -s loop loop`): an
    internal error (RuntimeError: Symlink loop), exit 1. Now one line naming the loop, exit 2, nothing written."""
    os.symlink("loop", tmp_path / "loop")
    code, lines = refused([*RUN, f"hydra.run.dir={tmp_path / 'loop' / 'run'}"], capsys)
    one_line(code, lines, "goes through a loop of symbolic links")
    with pytest.raises(ConfigError, match="goes through a loop of symbolic links"):
        ppo_torchrl.train(RUN, run_dir=tmp_path / "loop" / "run")
    code, lines = ran(evaluate.main, [f"run={run_copy}", "checkpoint=last", "episodes=1",
                                                  f"out={tmp_path / 'loop' / 'eval'}"], capsys)
    one_line(code, lines, "goes through a loop of symbolic links")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loop", "run"]


# ---------------------------------------------------------------- the report's text columns

def test_a_text_column_in_metrics_csv_is_not_called_damage(run_copy, capsys):
    """A column of text (a tag a logger or a user added) made `report` call metrics.csv damaged. Text columns are
    left out of the plots; a column of numbers with text in it, or a row cut short, is still damage."""
    path = run_copy / "metrics.csv"
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0] + ",note"] + [row + ",warm-up" for row in lines[1:]]) + "\n")
    assert "note" not in report.read_metrics(path) and len(report.read_metrics(path)["frames"]) == len(lines) - 1
    code, err = ran(report.main, [str(run_copy)], capsys)
    assert code == 0 and (run_copy / "report.png").is_file(), err
    path.write_text("\n".join([lines[0] + ",note"] + [row + ",3" for row in lines[1:]] + [lines[-1] + ",warm-up"])
                    + "\n")
    with pytest.raises(ConfigError, match="is damaged"):
        report.read_metrics(path)
    path.write_text("\n".join(lines + [lines[-1].rpartition(",")[0]]) + "\n")  # a row cut short
    with pytest.raises(ConfigError, match="is damaged"):
        report.read_metrics(path)


def test_a_symlink_loop_is_a_user_fixable_error_wherever_it_is_met():
    """(Beside the checks above) ELOOP met anywhere else is the one line of a path to fix, not an internal error."""
    from ppo_torchrl.errors import exit_code, message_of

    error = OSError(errno.ELOOP, "Too many levels of symbolic links", "x/loop")
    assert exit_code(error) == 1 and message_of(error).startswith("error: Too many levels of symbolic links writing x")


# ---------------------------------------------------------------- review mends (2026-12-02)

def test_tracking_and_drive_on_a_run_that_is_no_joystick_are_one_line(run_copy, capsys):
    """evaluate tracking=true / drive= on a Gymnasium run read env.legged's kwargs or built the batch of a model file
    the run has none of: a KeyError traceback, exit 1. Now one line naming what they measure, nothing written."""
    before = sorted(p.name for p in run_copy.iterdir())
    for option in ("tracking=true", "drive=forward:0.3,0,0:1"):
        code, lines = ran(evaluate.main, [f"run={run_copy}", "checkpoint=last", option], capsys)
        one_line(code, lines, "measures a joystick run")
    assert sorted(p.name for p in run_copy.iterdir()) == before


def test_filming_a_non_mujoco_env_leaves_its_floor_alone():
    """floor_to_the_horizon on an env without a MuJoCo model (Pendulum-v1, env=gym) took the env for a model:
    AttributeError on geom_type, so video=true of such a run ended in a traceback."""
    import gymnasium as gym

    from ppo_torchrl.envs.mjcf import floor_to_the_horizon

    env = gym.make("Pendulum-v1", render_mode="rgb_array")
    floor_to_the_horizon(env.unwrapped)  # nothing to widen, no error
    hopper = gym.make("Hopper-v4").unwrapped
    floor_to_the_horizon(hopper)
    assert hopper.model.geom_size[0, 0] > 20  # a MuJoCo env's plane is still widened
