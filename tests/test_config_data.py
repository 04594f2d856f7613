"""A checkpoint's config is data (issue 76 item 1): nothing read back from disk is built into a call or resolved.

A real checkpoint whose saved config names a call (`env.transforms.extra` with `_target_: pathlib.Path.unlink` of a
user's file, `torch.load` of a file beside the run through `${resume}`, `builtins.open(mode="w")` nested in a real
transform's arguments) passes the safe unpickler, since it is only strings: each route that builds an env from a
saved config (evaluate, export, `load()`, `evaluate_run()`, `resume=`) refuses it in one line with the user's file as
it was; `init_from=` never builds anything from it. An interpolation in a config read back (a checkpoint's config,
config.yaml, hydra.yaml's choices, a sweep job's overrides) is never resolved: a resolver that leaves a marker
proves it.
"""

import shutil
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

import ppo_torchrl
from ppo_torchrl.run import checkpoint
from ppo_torchrl.config import run_config
from ppo_torchrl.config_data import DATA_TRANSFORMS, read_yaml, transform_entry
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.run.lifecycle import resume_config
from ppo_torchrl.report import episode_kinds, sweep_runs
from ppo_torchrl.trainer import Trainer

from conftest import TINY, compose_config, run_cli

MARKER_RESOLVER = "test_config_data.ran"


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("finished") / "run"
    Trainer(compose_config(["env=InvertedPendulum-v4", *TINY]), run).train()
    return run


@pytest.fixture
def victim(tmp_path):
    """A user's file that a payload would delete or empty."""
    path = tmp_path / "user_notes.txt"
    path.write_text("the user's own words\n")
    return path


def payloads(victim: Path) -> dict:
    return {
        "unlink": [{"_target_": "pathlib.Path.unlink", "self": str(victim)}],
        "torch.load via ${resume}": [{"_target_": "torch.load", "f": "${resume}/notes.pt", "weights_only": False}],
        "open nested in CatFrames": [{"_target_": "torchrl.envs.CatFrames", "N": 2, "dim": -1,
                                      "in_keys": {"_target_": "builtins.open", "file": str(victim), "mode": "w"}}],
    }


def crafted_run(finished_run: Path, tmp_path: Path, extra: list) -> Path:
    """A copy of a real run whose checkpoints' saved config carries `extra` as env.transforms.extra."""
    run = Path(shutil.copytree(finished_run, tmp_path / "crafted_run"))
    for path in (run / "checkpoints").glob("*.pt"):
        state = checkpoint.load(path)
        state["config"]["env"]["transforms"]["extra"] = extra
        checkpoint.save(path, state)
    return run


def assert_untouched(victim: Path) -> None:
    assert victim.read_text() == "the user's own words\n"


def one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip() and not line.startswith("warning:")]
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr[-2000:]
    return lines[0]


@pytest.mark.parametrize("kind", ["unlink", "torch.load via ${resume}", "open nested in CatFrames"])
def test_evaluate_export_load_and_evaluate_run_refuse_a_saved_config_that_names_a_call(finished_run, tmp_path,
                                                                                        victim, kind):
    run = crafted_run(finished_run, tmp_path, payloads(victim)[kind])
    expected = "interpolation" if "${" in kind else "_target_"
    for module, args in (("ppo_torchrl.evaluate", ["episodes=1", f"out={tmp_path / 'eval'}"]),
                         ("ppo_torchrl.export", [])):
        result = run_cli(f"run={run}", "checkpoint=last", *args, module=module)
        assert result.returncode == 2 and expected in one_error_line(result.stderr), (module, result.stderr[-1500:])
        assert_untouched(victim)
    assert not (run / "policy.pt").exists() and not (tmp_path / "eval").exists()
    with pytest.raises(ConfigError, match=expected):
        ppo_torchrl.load(run, checkpoint="last")
    with pytest.raises(ConfigError, match=expected):
        ppo_torchrl.evaluate_run(run, episodes=1, checkpoint="last")
    assert_untouched(victim)


def test_resume_refuses_a_saved_config_that_names_a_call_and_init_from_builds_nothing_of_it(finished_run, tmp_path,
                                                                                              victim):
    run = crafted_run(finished_run, tmp_path, payloads(victim)["unlink"])
    before = {p.name: p.read_bytes() for p in (run / "checkpoints").iterdir()}
    result = run_cli(f"resume={run}", "collector.total_frames=1024")
    assert result.returncode == 2 and "pathlib.Path.unlink" in one_error_line(result.stderr), result.stderr[-1500:]
    assert_untouched(victim)
    assert {p.name: p.read_bytes() for p in (run / "checkpoints").iterdir()} == before  # nothing on disk changed
    # init_from takes weights and statistics; the source's config is only named on the start line
    new = tmp_path / "new"
    result = run_cli("env=InvertedPendulum-v4", *TINY, f"init_from={run / 'checkpoints' / 'last.pt'}",
                     f"hydra.run.dir={new}")
    assert result.returncode == 0, result.stderr[-1500:]
    assert_untouched(victim)
    assert (new / "checkpoints" / "last.pt").is_file()


def test_the_command_line_is_held_to_the_same_rule(tmp_path, victim):
    for extra in ("[{_target_:pathlib.Path.unlink,self:" + str(victim) + "}]",
                  "[{_target_:torchrl.envs.transforms.r3m.R3MTransform,model_name:resnet18}]",
                  "[{_target_:torchrl.envs.RayTransform}]"):
        result = run_cli("env=InvertedPendulum-v4", *TINY, f"env.transforms.extra={extra}",
                         f"hydra.run.dir={tmp_path / 'run'}")
        assert result.returncode == 2 and "is not a TorchRL transform this app builds" in one_error_line(result.stderr)
        assert_untouched(victim) and not (tmp_path / "run").exists()
    # a transform of the list, by either public path, is built as before
    for target in ("torchrl.envs.CatFrames", "torchrl.envs.transforms.CatFrames"):
        cls, args, kwargs = transform_entry(OmegaConf.create({"_target_": target, "N": 2, "dim": -1,
                                                             "in_keys": ["observation"]}), "x")
        assert cls.__name__ == "CatFrames" and args == [] and kwargs == {"N": 2, "dim": -1, "in_keys": ["observation"]}
    import torchrl.envs.transforms as transforms

    assert all(isinstance(getattr(transforms, name), type) and issubclass(getattr(transforms, name), transforms.Transform)
               for name in DATA_TRANSFORMS)


@pytest.fixture
def marker_resolver(tmp_path):
    """A resolver that leaves a marker when an interpolation naming it is resolved."""
    marker = tmp_path / "resolved"

    def ran(*_):
        marker.write_text("resolved")
        return "x"

    OmegaConf.register_new_resolver(MARKER_RESOLVER, ran, replace=True)
    yield marker, "${" + MARKER_RESOLVER + ":}"
    OmegaConf.clear_resolver(MARKER_RESOLVER)


def test_no_interpolation_read_back_from_disk_is_resolved(finished_run, tmp_path, marker_resolver):
    marker, interpolation = marker_resolver
    run = Path(shutil.copytree(finished_run, tmp_path / "run"))
    state = checkpoint.load(run / "checkpoints" / "last.pt")
    state["config"]["logger"]["project"] = interpolation
    with pytest.raises(ConfigError, match="logger.project=.* is an interpolation"):
        run_config(run, state)
    # config.yaml (report's labels, evaluate's same-env check), hydra.yaml's choices (resume), overrides.yaml (sweeps)
    saved = OmegaConf.to_container(OmegaConf.load(run / "config.yaml"))
    saved["env"]["terrain"] = interpolation
    (run / "config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.create(saved)))
    assert episode_kinds(run) == ("", "")
    with pytest.raises(ConfigError, match="interpolation"):
        read_yaml(run / "config.yaml")
    hydra_dir = run / ".hydra"
    hydra_dir.mkdir(exist_ok=True)
    (hydra_dir / "hydra.yaml").write_text(f"hydra:\n  runtime:\n    choices:\n      logger: '{interpolation}'\n")
    good = checkpoint.load(finished_run / "checkpoints" / "last.pt")
    with pytest.raises(ConfigError, match="differs from the run's|resume"):
        resume_config(run, ["logger=none"], good)
    sweep = tmp_path / "sweep"
    job = Path(shutil.copytree(finished_run, sweep / "0_seed=1"))
    (job / ".hydra").mkdir(exist_ok=True)
    (job / ".hydra" / "overrides.yaml").write_text(f"- seed=1\n- logger.project={interpolation}\n")
    groups, _ = sweep_runs(sweep)
    assert list(groups) == [(f"logger.project={interpolation}",)]
    assert not marker.exists()


def test_a_saved_config_still_loads_and_a_real_transform_still_runs(tmp_path):
    """What the rule leaves working: a run with a transform from the list trains, evaluates and resumes."""
    run = tmp_path / "run"
    extra = "env.transforms.extra=[{_target_:torchrl.envs.CatFrames,N:2,dim:-1,in_keys:[observation]}]"
    assert run_cli("env=InvertedPendulum-v4", *TINY, extra, f"hydra.run.dir={run}").returncode == 0
    state = checkpoint.load(run / "checkpoints" / "last.pt")
    assert state["config"]["env"]["transforms"]["extra"][0]["_target_"] == "torchrl.envs.CatFrames"
    result = ppo_torchrl.evaluate_run(run, episodes=1, checkpoint="last")
    assert result["return_mean"] > 0
    assert isinstance(torch.load(run / "checkpoints" / "last.pt", weights_only=True), dict)
