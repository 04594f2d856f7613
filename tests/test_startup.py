"""The start-up line (frame budget, what env files and presets change) and resume ergonomics."""

from ppo_torchrl.startup import describe_start

from conftest import compose_config


def start_line(*overrides):
    return describe_start(compose_config(list(overrides)), list(overrides))


def test_start_line_says_the_frame_budget_is_rounded_up():
    line = start_line("experiment=aidl_anymal", "collector.total_frames=8192")
    assert "2 batches x 6400 = 12,800 frames (collector.total_frames=8192 rounded up)" in line
    assert "loss.epochs=48" in line and "collector.total_frames" not in line.split(";", 1)[1]


def test_start_line_names_what_the_env_file_changes_but_not_the_command_line():
    line = start_line("env=HalfCheetah-v4", "policy.width=64", "optim.lr=0.001", "loss=a2c")
    assert line.startswith("start: HalfCheetah-v4, 1954 batches x 512 = 1,000,448 frames")
    changed = line.split("; set by the env file/preset: ", 1)[1].split(", ")
    assert "loss.epochs=20" in changed and "policy.activation=relu" in changed
    assert not [c for c in changed if c.startswith(("policy.width", "optim.lr", "loss.name", "env.", "seed"))]


def test_start_line_of_an_exact_budget_and_the_defaults():
    line = start_line("env=InvertedPendulum-v4", "collector.total_frames=4096")
    assert line == "start: InvertedPendulum-v4, 2 batches x 2048 = 4,096 frames; the env file/preset changes no defaults"
