"""What is safe to load (issue 60): a checkpoint is data, never code.

A crafted `.pt` whose unpickling would run a command (here: create a marker file), given as `checkpoint=` to
evaluate, `init_from=` or `resume=` to training, or a crafted env state packed inside a real checkpoint, is one
`error:` line naming the file and exit 2, and the marker never appears; every checkpoint the app wrote (zoo/,
results/) still loads, through the same safe path.
"""

import os
import pickle
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from ppo_torchrl.run import checkpoint
from ppo_torchrl.__main__ import prepare
from ppo_torchrl.envs.state import PACKED, pack, unpack
from ppo_torchrl.errors import ConfigError, guarded
from ppo_torchrl.trainer import Trainer

from conftest import ROOT, TINY, compose_config, run_cli


class Payload:
    """Unpickling this runs `touch <marker>`."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {shlex.quote(str(self.marker))}",)


@pytest.fixture
def crafted(tmp_path):
    """(a crafted checkpoint: a real one's keys, a payload in its config; the marker its payload would create)."""
    marker = tmp_path / "payload_ran"
    path = tmp_path / "crafted.pt"
    checkpoint.save(path, {"actor": {}, "critic": {}, "frames": 512, "config": Payload(marker)})
    return path, marker


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    """A real finished tiny run (2 batches of 256 frames, a checkpoint each)."""
    run = tmp_path_factory.mktemp("finished") / "run"
    Trainer(compose_config(["env=InvertedPendulum-v4", *TINY]), run).train()
    return run


def one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr[-2000:]
    return lines[0]


def refused(args, capsys):
    """The training entry point's checks in-process: (exit code, stderr lines)."""
    with pytest.raises(SystemExit) as exit_:
        guarded(prepare, args)
    return exit_.value.code, capsys.readouterr().err


def test_a_crafted_checkpoint_is_refused_before_it_runs(crafted):
    path, marker = crafted
    with pytest.raises(ConfigError, match="not safe to load: it asks for posix.system") as error:
        checkpoint.load(path)
    assert str(path) in str(error.value) and not marker.exists()


def test_a_crafted_checkpoint_given_to_evaluate_is_one_line_and_never_runs(crafted, finished_run):
    path, marker = crafted
    result = run_cli(f"run={finished_run}", f"checkpoint={path}", "episodes=1", module="ppo_torchrl.evaluate")
    assert result.returncode == 2 and str(path) in one_error_line(result.stderr) and not marker.exists()


def test_a_crafted_checkpoint_given_as_init_from_is_one_line_and_never_runs(crafted, tmp_path):
    path, marker = crafted
    result = run_cli("env=InvertedPendulum-v4", *TINY, f"init_from={path}", f"hydra.run.dir={tmp_path / 'new'}")
    assert result.returncode == 2 and str(path) in one_error_line(result.stderr) and not marker.exists()


def crafted_env_state(state: dict, marker: Path, nested: bool) -> dict:
    """`state` with its collector's packed state (or the EnvState's, packed inside that one) a payload."""
    collector = state["normalization"]["collector"]
    if not nested:
        return {**state, "normalization": {**state["normalization"], "collector": pack(Payload(marker))}}
    opened = unpack(collector)
    env_states = opened["env_state_dict"]
    key = next(k for k, v in env_states.items() if isinstance(v, dict) and PACKED in v)
    opened["env_state_dict"] = {**env_states, key: pack(Payload(marker))}
    return {**state, "normalization": {**state["normalization"], "collector": pack(opened)}}


@pytest.mark.parametrize("nested", [False, True], ids=["collector state", "EnvState inside it"])
def test_a_crafted_env_state_inside_a_real_checkpoint_is_refused(finished_run, tmp_path, capsys, nested):
    run = Path(shutil.copytree(finished_run, tmp_path / "run"))
    last = run / "checkpoints" / "last.pt"
    marker = tmp_path / "payload_ran"
    checkpoint.save(last, crafted_env_state(checkpoint.load(last), marker, nested))
    code, err = refused([f"resume={run}", "collector.total_frames=1024"], capsys)
    line = one_error_line(err)
    assert code == 2 and str(last) in line and "posix.system" in line and not marker.exists()
    with pytest.raises(pickle.UnpicklingError):  # unpack, also between worker processes, reads data only
        unpack(pack(Payload(marker)))
    assert not marker.exists()


def test_a_packed_state_keeps_what_it_holds():
    rng = np.random.default_rng(3)
    state = {"stats": {"mean": np.arange(3.0), "count": np.float64(7.5), "n": np.int64(2)},
             "rng": rng.bit_generator.state, "python": (3, tuple(range(5)), None), "flags": [True, False],
             "tensor": torch.arange(4, dtype=torch.float32), "inner": pack({"obs": np.ones((2, 2), np.float32)})}
    back = unpack(pack(state))
    np.testing.assert_array_equal(back["stats"]["mean"], state["stats"]["mean"])
    assert back["stats"]["count"] == 7.5 and back["stats"]["n"].dtype == np.int64
    assert back["rng"] == state["rng"] and back["python"] == state["python"] and back["flags"] == [True, False]
    assert torch.equal(back["tensor"], state["tensor"])
    np.testing.assert_array_equal(unpack(back["inner"])["obs"], np.ones((2, 2), np.float32))


def test_every_checkpoint_the_app_wrote_loads_through_the_safe_path():
    shipped = sorted(ROOT.glob("zoo/**/*.pt")) + sorted(ROOT.glob("results/**/*.pt"))
    # a run going on under results/ rotates its rolling checkpoints (git-ignored, never shipped) away mid-test
    shipped = [path for path in shipped if not path.name.startswith("frames_")]
    assert shipped
    for path in shipped:
        state = checkpoint.load(path)  # weights_only, and every packed env state read as data
        assert state["actor"] and state["frames"] > 0, path
