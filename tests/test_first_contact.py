"""Issue 49: the mistakes a user of SB3, rl-zoo or CleanRL makes first, each one line with the fix; counts
written 1e6; the learning-rate schedule of an extended run."""

import pytest

from ppo_torchrl.__main__ import prepare
from ppo_torchrl.compose import compose
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.overrides import whole_counts


@pytest.mark.parametrize("argv, fix", [
    (["env=Hoper-v4"], "did you mean env=Hopper-v4?"),
    (["env=Swimer-v4"], "did you mean env=gym env.id=Swimmer-v4?"),  # no file, but a Gymnasium id is near
    (["env=Swimmer-v4"], "Swimmer-v4 is a Gymnasium id: env=gym env.id=Swimmer-v4"),
    (["colector.total_frames=1000"], "did you mean collector.total_frames?"),
    (["collector.totl_frames=1000"], "did you mean collector.total_frames?"),
    (["env=Hopper-v4", "env.max_episod_steps=5"], "did you mean env.max_episode_steps?"),
    (["--env", "Hopper-v4"], "not --key value; write env=Hopper-v4"),
    (["--total-timesteps=1e6"], "write collector.total_frames=1e6"),
    (["env=Hopper-v4", "--learning-rate", "3e-4"], "write optim.lr=3e-4"),
])
def test_a_mistake_names_its_fix(argv, fix):
    with pytest.raises(ConfigError) as error:
        prepare(argv)
    assert fix in str(error.value) and "\n" not in str(error.value), str(error.value)


def test_counts_written_like_1e6_are_the_ints_they_are():
    argv = ["env=Hopper-v4", "collector.total_frames=1e6", "collector.frames_per_batch=2.048e3", "optim.lr=3e-4",
            "eval.every_frames=1e5,2e5"]
    overrides = list(argv)
    argv, overrides = whole_counts(argv, overrides, compose)
    assert overrides == argv == ["env=Hopper-v4", "collector.total_frames=1000000", "collector.frames_per_batch=2048",
                                 "optim.lr=3e-4", "eval.every_frames=100000,200000"]  # a float stays a float
    cfg = compose(overrides[:4])
    assert cfg.collector.total_frames == 1_000_000 and cfg.optim.lr == 3e-4
    with pytest.raises(ConfigError, match="could not be converted to Integer"):  # not a whole number: Hydra's word
        compose(whole_counts(["collector.total_frames=1.5e0"], ["collector.total_frames=1.5e0"], compose)[1])


def test_extending_a_run_continues_its_lr_schedule(tiny_cfg, tmp_path):
    """resume= with more collector.total_frames: the lr goes on down from the last update's to 0 at the new
    end (before: back up to where a run of the new length would be, 0.5 -> 0.75 x optim.lr here)."""
    import csv

    from ppo_torchrl.run import checkpoint
    from ppo_torchrl.trainer import Trainer

    cfg = tiny_cfg("collector.total_frames=512", "logger=csv")
    Trainer(cfg, tmp_path).train()
    state = checkpoint.load(tmp_path / "checkpoints" / "last.pt")
    longer = tiny_cfg("collector.total_frames=2048", "logger=csv")
    Trainer(longer, tmp_path, resume=state).train()
    with open(tmp_path / "metrics.csv") as f:
        lrs = [float(row["lr"]) / cfg.optim.lr for row in csv.DictReader(f)]
    assert len(lrs) == 8 and lrs[:2] == [1.0, 0.5]
    assert all(b < a for a, b in zip(lrs, lrs[1:])) and lrs[-1] > 0  # down at every update, across the resume
    assert abs(lrs[2] - 0.5 * 6 / 7) < 1e-4 and abs(lrs[-1] - 0.5 / 7) < 1e-4  # 0.5 to 0 over the 7 steps left


def test_the_eta_leaves_the_warm_up_out(capsys, monkeypatch):
    """The first progress line has no ETA (its iteration holds the compile warm-up); later ones use the rate
    of the recent iterations, not the run's mean SPS that the warm-up drags down."""
    from ppo_torchrl.run import loggers

    clock = iter([60.0, 61.0, 62.0])  # the first iteration ends after 60 s of warm-up, then 1 s per 1000 frames
    monkeypatch.setattr(loggers.time, "perf_counter", lambda: next(clock))
    progress = loggers.Progress(total_frames=100_000, start_frames=0, every_s=0.0, tty=False)
    for frames in (1000, 2000, 3000):
        progress.update({"frames": frames, "sps": frames / 60}, 1000, force=False)
    lines = capsys.readouterr().err.splitlines()  # with the start and done lines
    assert lines[0].endswith("eta after warm-up"), lines
    assert lines[2].endswith("eta   1.6 min"), lines  # 97,000 frames at 1000/s, not at the mean's 50/s


# ---------------------------------------------------------------- issue 76 item 4: first contact, round 4

def readme() -> str:
    from conftest import ROOT

    return (ROOT / "README.md").read_text()


def test_the_readme_shows_the_newest_reported_robot_round():
    """The README's robot section was issue 46's table (its 80% goal, Go1 at 0%), then v2's; the newest reported round
    is recipe v3's twelve rows (results/robots/legged_v3_2026-12-02/table.md): the README's table is the table.md's last
    one (`robots_table.py --goals 59`'s per-robot table) cell for cell, robots under their display names, with the
    round's seeds, episode seeds, goals' tally and commands."""
    import re

    from conftest import ROOT

    text = readme()
    assert "results/robots/legged_v3_2026-12-02" in text and "docs/robots_round2.md" in text
    assert "goal 80%" not in text and "seeds 14 and 15" in text and "62000-62099" in text
    assert "make robot RECIPE=legged_trot_v3" in text and len(text.splitlines()) <= 300
    table = (ROOT / "results" / "robots" / "legged_v3_2026-12-02" / "table.md").read_text()
    last = [block for block in table.split("\n\n") if block.lstrip().startswith("|")][-1].strip().splitlines()
    names = {"a1": "A1", "go2": "Go2", "spot": "Spot", "barkour_vb": "Barkour vB", "go1": "Go1", "anymal_b": "ANYmal B"}
    rows = [re.sub(r"^\| (\w+) \(", lambda m: f"| {names[m.group(1)]} (", row) for row in last[2:]]
    assert len(rows) == 6 and all(row in text.splitlines() for row in rows), rows
    met = re.search(r"^Goals met: (\d+) of 84", text, re.M)
    tally = sum(int(n) for row in rows for n in row.rstrip(" |").rsplit("|", 1)[1].split("/"))
    assert met and int(met.group(1)) == tally, (met, tally)


def test_the_readme_says_how_to_clone_shallow_shrink_make_robot_and_pick_envpool():
    text = readme()
    assert "git clone --depth 1" in text
    assert all(knob in text for knob in ("EPISODES=", "HEIGHTS=", "ARGS="))
    assert "backend` (auto, fast, torchrl, envpool)" in text


def test_every_hint_that_lists_robots_names_the_six_shipped_ones(tmp_path):
    """A wrong model path's hint listed the in-house models (quadruped.xml, ...) and not the six Menagerie robots; the
    --help page's env group named only the in-house ones."""
    from conftest import ROOT
    from ppo_torchrl.envs.make import resolve_model_file
    from ppo_torchrl.shipped import robots

    assert len(robots()) == 6
    with pytest.raises(ConfigError) as error:
        resolve_model_file(str(tmp_path / "no_such_scene.xml"))
    assert all(robot in str(error.value) for robot in robots()), str(error.value)
    page = (ROOT / "conf" / "hydra" / "help" / "ppo_torchrl.yaml").read_text()
    assert all(robot.split("/")[1] in page for robot in robots()) and "envpool" in page


def test_the_start_line_says_what_device_auto_picked_and_credits_the_apis_overrides_to_the_user(tmp_path, capsys):
    """device=auto did not say what it picked; a run started by the API credited the user's overrides to the env file
    ('set by the env file/preset: collector.frames_per_batch=256, ...')."""
    import ppo_torchrl
    from conftest import TINY

    ppo_torchrl.train(["env=InvertedPendulum-v4", *TINY, "device=auto"], run_dir=tmp_path / "run")
    start = next(line for line in capsys.readouterr().err.splitlines() if line.startswith("start: "))
    assert "; device=auto: cpu (no CUDA device)" in start or "; device=auto: cuda (" in start, start
    assert "frames_per_batch" not in start and "loss.epochs" not in start, start


def test_evaluates_misspelt_env_key_gets_the_closest_one(tmp_path):
    """evaluate's env.<key>=<value> misspelt: omegaconf's line, no did-you-mean (the training command had one)."""
    from conftest import TINY, compose_config
    from ppo_torchrl.evaluate import apply_overrides

    with pytest.raises(ConfigError, match=r"did you mean env\.max_episode_steps\?"):
        apply_overrides(compose_config(["env=InvertedPendulum-v4", *TINY]), ["env.max_episod_steps=5"])


def test_a_shipped_run_is_only_read_and_heights_in_metres_say_so(tmp_path, monkeypatch, capsys):
    """evaluate and export of a shipped run under results/ wrote into the tracked tree (eval/, policy.pt) and rewrote
    its manifest; export had no out=. Now their files go under outputs/<the run's path>/ (or out=), the run as it was
    shipped. And heights=0,0.1 on a legged run (every value below 1) says once that they are metres, not leg lengths."""
    from conftest import ROOT
    from test_bad_input import tree_digest

    from ppo_torchrl import evaluate, export

    run = ROOT / "results" / "robots" / "legged_v2_2026-11-28" / "go1_seed12"
    before = tree_digest(run)
    monkeypatch.chdir(tmp_path)
    evaluate.main([f"run={run}", "checkpoint=last", "episodes=1", "heights=0,0.1"])
    notes = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note: ")]
    assert sum("are in m" in line and "heights=0,0.1l" in line for line in notes) == 1, notes
    mirrored = tmp_path / "outputs" / "results" / "robots" / "legged_v2_2026-11-28" / "go1_seed12"
    assert (mirrored / "height_sweep.csv").is_file()
    assert export.main([f"run={run}", "checkpoint=last"]).resolve() == (mirrored / "policy.pt").resolve()
    assert export.main([f"run={run}", "checkpoint=last", f"out={tmp_path / 'mine.pt'}"]) == tmp_path / "mine.pt"
    assert tree_digest(run) == before


def test_export_outside_a_run_names_its_deploy_files_after_the_policy_and_leaves_a_users_files(tmp_path, capsys):
    """export out=<dir>/mine.pt of a legged run wrote policy.onnx, policy.json and deploy_mujoco.py beside it, over a
    user's files of those names (no run dir's manifest there to ask), and the deploy script looked for policy.pt.
    Now they are mine.onnx and mine.json (which names mine.pt, the script's default), and a file already there with
    other bytes is one line, exit 2, before anything is written; the same export again changes no byte."""
    import json

    from conftest import ROOT, ran
    from ppo_torchrl import export
    from ppo_torchrl.tasks.locomotion import deploy_mujoco

    run = ROOT / "results" / "robots" / "legged_v2_2026-11-28" / "go1_seed12"
    out = tmp_path / "robot"
    out.mkdir()
    (out / "mine.json").write_text("the user's own\n")
    code, lines = ran(export.main, [f"run={run}", "checkpoint=last", f"out={out / 'mine.pt'}"], capsys)
    assert code == 2 and len(lines) == 1 and lines[0].startswith(f"error: {out / 'mine.json'} exists"), lines
    assert sorted(p.name for p in out.iterdir()) == ["mine.json"]
    assert (out / "mine.json").read_text() == "the user's own\n"
    (out / "mine.json").unlink()
    assert export.main([f"run={run}", "checkpoint=last", f"out={out / 'mine.pt'}"]) == out / "mine.pt"
    assert sorted(p.name for p in out.iterdir()) == ["deploy_mujoco.py", "mine.json", "mine.onnx", "mine.pt"]
    assert json.loads((out / "mine.json").read_text())["policy"] == "mine.pt"
    siblings = {p.name: p.read_bytes() for p in out.iterdir() if p.name != "mine.pt"}
    export.main([f"run={run}", "checkpoint=last", f"out={out / 'mine.pt'}"])  # the same bytes: nothing refused
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.name != "mine.pt"} == siblings
    capsys.readouterr()
    assert deploy_mujoco.main([str(out / "mine.json"), "--commands", "forward:0.3,0,0:0.1"]) == 0  # mine.pt, found
    assert json.loads(capsys.readouterr().out.splitlines()[0])["segment"] == "forward"
