"""Reliability round 5 (issue 60): a path is a path (an output dir is compared with run dirs by where it really
is), a file is the app's only if the app wrote it (what evaluate, export and report write is recorded by its
bytes when they write it), empty or absurd values are one line, other tools' words get this app's, and a run
interrupted after its last batch can be finished. Refused commands leave every file as it was."""

from __future__ import annotations

import json
import os
import time

import pytest

from conftest import ran, run_cli
from ppo_torchrl import evaluate, export, report
from ppo_torchrl.run import rundir
from ppo_torchrl.run.lifecycle import Lifecycle
from test_bad_input import finished_run, refused, tree_digest  # noqa: F401  (the module's finished run)
from test_reliability_round3 import RUN, copy_of


def users_eval(run):
    """A user's eval/eval.json in a run dir, which the run's manifest does not list."""
    (run / "eval").mkdir(exist_ok=True)
    (run / "eval" / "eval.json").write_text('{"mine": true}\n')
    return run


# ---------------------------------------------------------------- 1. a path is a path

@pytest.mark.parametrize("spelling", ["dotdot", "relative", "symlinked"])
def test_an_out_dir_spelled_another_way_is_still_the_run_dir(finished_run, tmp_path, capsys, monkeypatch, spelling):
    """out=<run's parent>/../<parent>/run/eval, the same dir relative from elsewhere, or through a symlink to the run's parent: the
    user's eval/eval.json in the run is refused in one line, as with the plain spelling."""
    run = users_eval(copy_of(finished_run, tmp_path))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    if spelling == "symlinked":
        os.symlink(tmp_path, tmp_path / "elsewhere" / "alias")
    out = {"dotdot": f"{tmp_path}/../{tmp_path.name}/run/eval", "relative": "../run/eval",
           "symlinked": "alias/run/eval"}[spelling]
    before = tree_digest(run)
    code, lines = ran(evaluate.main, [f"run={run}", "episodes=1", f"out={out}"], capsys)
    assert code == 2 and len(lines) == 1 and "is not a file this app wrote" in lines[0], lines
    assert tree_digest(run) == before


def test_out_in_another_run_is_answered_by_that_runs_manifest(finished_run, tmp_path, capsys):
    """evaluate run=A out=B/eval: B's manifest is asked (B's user file refused), and what evaluate writes in B is
    listed in B's manifest, so B stays a run dir holding only the app's files."""
    a = copy_of(finished_run, tmp_path, "a")
    b = users_eval(copy_of(finished_run, tmp_path, "b"))
    before = tree_digest(tmp_path)
    code, lines = ran(evaluate.main, [f"run={a}", "episodes=1", f"out={b}/eval"], capsys)
    assert code == 2 and len(lines) == 1 and f"{b}/eval/eval.json is not a file this app wrote" in lines[0], lines
    assert tree_digest(tmp_path) == before
    (b / "eval" / "eval.json").unlink()
    code, lines = ran(evaluate.main, [f"run={a}", "episodes=1", f"out={b}/eval"], capsys)
    assert code == 0, lines
    assert "eval/eval.json" in rundir.listed(b) and rundir.foreign_files(b) == []


# ---------------------------------------------------------------- 2. a file is the app's only if the app wrote it

def test_a_policy_or_report_put_in_a_run_while_it_resumes_is_never_listed(finished_run, tmp_path, capsys):
    """A user's policy.pt and report.png written while a resume trains (here: just before the resume's listing,
    which every checkpoint makes) are not listed: export and report refuse them in one line."""
    run = copy_of(finished_run, tmp_path)
    (run / "policy.pt").write_bytes(b"the user's policy")
    (run / "report.png").write_bytes(b"the user's figure")
    rundir.record(run)  # the resume's listing: what this process wrote since it began
    assert "policy.pt" not in rundir.listed(run) and "report.png" not in rundir.listed(run)
    before = tree_digest(run)
    for main, args, name in ((export.main, [f"run={run}"], "policy.pt"), (report.main, [str(run)], "report.png")):
        code, lines = ran(main, args, capsys)
        assert code == 2 and len(lines) == 1 and f"{name} is not a file this app wrote" in lines[0], lines
    assert tree_digest(run) == before


def test_a_file_dated_in_the_future_is_not_taken_for_one_the_run_wrote(finished_run, tmp_path):
    """tar x / cp -p / clock skew: a user's logs/notes.txt dated tomorrow is not listed by the run's listing, so
    overwrite=true names it instead of taking it for the app's."""
    run = copy_of(finished_run, tmp_path)
    notes = run / "logs" / "notes.txt"
    notes.parent.mkdir(exist_ok=True)
    notes.write_text("mine")
    tomorrow = time.time_ns() + 86_400 * 10**9
    os.utime(notes, ns=(tomorrow, tomorrow))
    rundir.record(run)
    assert "logs/notes.txt" not in rundir.listed(run) and rundir.foreign_files(run) == ["logs/notes.txt"]


@pytest.mark.parametrize("target", ["policy.pt", "report.png", "eval/eval.json"])
def test_a_file_the_app_wrote_and_the_user_replaced_is_not_replaced_again(finished_run, tmp_path, capsys, target):
    """The app wrote policy.pt (report.png, eval/eval.json), listed with the sha256 of its bytes; the user puts
    their own file of that name there (same name, same place): the next export (report, evaluate) refuses it in
    one line naming it. The app's own file, in a copy of the run, is replaced as before."""
    run = copy_of(finished_run, tmp_path)
    main, args = {"policy.pt": (export.main, [f"run={run}"]), "report.png": (report.main, [str(run)]),
                  "eval/eval.json": (evaluate.main, [f"run={run}", "episodes=1"])}[target]
    code, lines = ran(main, args, capsys)
    assert code == 0 and target in rundir.listed(run), lines
    copy = copy_of(run, tmp_path, "copy")
    code, lines = ran(main, [a.replace(str(run), str(copy)) for a in args], capsys)
    assert code == 0, lines  # the app's file, wherever the run was copied: replaced
    (run / target).write_bytes(b"the user's")
    before = tree_digest(run)
    code, lines = ran(main, args, capsys)
    assert code == 2 and len(lines) == 1 and f"{target} is not a file this app wrote: its bytes changed" in lines[0]
    assert tree_digest(run) == before


def test_a_write_cut_after_its_listing_leaves_a_file_the_next_command_replaces(tmp_path):
    """The listing names the old bytes and the new ones until the write is recorded: a kill before the rename
    (the old file) or after it (the new one) leaves a file the app may replace; a user's bytes are refused."""
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.ownership import digest

    run = tmp_path / "run"
    life = Lifecycle()
    life.claim(run)
    life.commit(run)
    rundir.atomic_write_bytes(run / "policy.pt", lambda f: f.write(b"old"), owner=run)
    rundir.record(run, [run / "policy.pt"])
    (run / "new").write_bytes(b"new")
    rundir.intend(run, [run / "policy.pt"], {run / "policy.pt": digest(run / "new")})  # then a kill
    rundir.check_replaceable(run, [run / "policy.pt"])  # the old bytes: the app's
    os.replace(run / "new", run / "policy.pt")
    rundir.check_replaceable(run, [run / "policy.pt"])  # the new bytes: the app's
    (run / "policy.pt").write_bytes(b"the user's")
    with pytest.raises(ConfigError, match="its bytes changed"):
        rundir.check_replaceable(run, [run / "policy.pt"])
    life.finish()


# ---------------------------------------------------------------- 3. empty or absurd values are bad input

@pytest.mark.parametrize("args, expected", [
    (["resume="], "resume=: the value is empty (an unset shell variable?) and a new run would start"),
    (["resume=''"], "the value is empty"),
    ([*RUN, "init_from="], "init_from=: the value is empty (an unset shell variable?) and the run would train from"),
    ([*RUN, "~seed"], "~seed: '~' deletes seed, which the app reads; set it instead (seed=<value>)"),
])
def test_an_empty_path_or_a_deleted_key_is_one_line(args, expected, tmp_path, capsys):
    if not any(a.startswith("resume=") for a in args):
        args = [*args, f"hydra.run.dir={tmp_path / 'new'}"]
    code, lines = refused(args, capsys)
    assert code == 2 and len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], lines
    assert not (tmp_path / "new").exists()


@pytest.mark.parametrize("args, expected", [
    (["episodes=1e11"], "episodes=100000000000 must be at most 1,000,000"),
    (["heights=0,1e9"], "heights=0,1e9: a step of 1e+09 is taller than any robot here can meet (at most 2 m"),
    (["heights=0.1,9l"], "a step of 9 is taller than any robot here can meet"),
])
def test_evaluate_refuses_absurd_counts_and_heights_in_one_sane_line(finished_run, tmp_path, capsys, args, expected):
    before = tree_digest(finished_run)
    code, lines = ran(evaluate.main, [f"run={finished_run}", *args], capsys)
    assert code == 2 and len(lines) == 1 and expected in lines[0], lines
    assert "-9570" not in lines[0] and tree_digest(finished_run) == before


def test_a_checkpoint_with_a_negative_frame_count_is_one_line_naming_it(finished_run, tmp_path, capsys):
    import torch

    run = copy_of(finished_run, tmp_path)
    last = run / "checkpoints" / "last.pt"
    state = torch.load(last, weights_only=False)
    torch.save({**state, "frames": -4096}, last)
    before = tree_digest(run)
    code, lines = refused([f"resume={run}"], capsys)
    assert code == 2 and len(lines) == 1 and f"checkpoint '{last}' is damaged: its frames count is -4096" in lines[0]
    assert "-4,096" not in lines[0] and tree_digest(run) == before


# ---------------------------------------------------------------- 4. other tools' words

@pytest.mark.parametrize("args", [["--algo", "ppo"], ["--algo=ppo"], ["algo=ppo"], ["--algo", "sac"]])
def test_algo_is_told_this_app_is_ppo_never_another_algorithm(args, tmp_path, capsys):
    code, lines = refused([*RUN, *args, f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    assert code == 2 and len(lines) == 1, lines
    assert "this app is PPO already (clipped PPO: the default loss=clip_ppo)" in lines[0]
    assert "one of clip_ppo, kl_ppo, ppo, a2c, reinforce" in lines[0] and "write loss=" not in lines[0], lines


@pytest.mark.parametrize("word, key", [("total_timesteps", "collector.total_frames"),
                                       ("total_frames", "collector.total_frames"), ("n_envs", "collector.num_envs"),
                                       ("num_envs", "collector.num_envs")])
def test_other_tools_words_as_overrides_get_this_apps_key(word, key, tmp_path, capsys):
    code, lines = refused(["env=InvertedPendulum-v4", f"{word}=4", f"hydra.run.dir={tmp_path / 'new'}"], capsys)
    assert code == 2 and len(lines) == 1 and f"did you mean {key}?" in lines[0], lines


# ---------------------------------------------------------------- 5. an interrupted run can always be finished

@pytest.mark.parametrize("during_eval", [False, True])
def test_a_run_stopped_after_its_last_batch_is_finished_by_resume(tiny_cfg, tmp_path, during_eval):
    """Ctrl-C in the last iteration (or in its final eval): every frame trained, no final eval, status interrupted.
    resume= runs the final eval, writes its figures into the last row and the summary, and marks the run
    finished; the stop's line says so."""
    import signal

    from ppo_torchrl.errors import Interrupted
    from ppo_torchrl.trainer import Trainer

    run = tmp_path / "run"
    trainer = Trainer(tiny_cfg("eval.final_episodes=2"), run)
    if during_eval:
        evaluate_ = trainer._evaluate
        trainer._evaluate = lambda *a, **k: (os.kill(os.getpid(), signal.SIGINT), evaluate_(*a, **k))[1]
    else:
        collect = trainer.collector.collect
        trainer.collector.collect = lambda: (trainer.iteration == 1 and os.kill(os.getpid(), signal.SIGINT),
                                             collect())[1]
    with pytest.raises(Interrupted) as stopped:
        trainer.train()
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "interrupted" and summary["frames"] == 512 and summary["eval_return_mean"] is None
    result = run_cli(f"resume={run}")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "the final eval runs and the run is marked finished" in result.stderr
    summary = json.loads((run / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["frames"] == 512 and summary["eval_return_mean"] is not None
    rows = (run / "metrics.csv").read_text().splitlines()
    header, last = rows[0].split(","), rows[-1].split(",")
    assert len(rows) == 3 and last[header.index("eval/return_mean")] != "", rows
    result = run_cli(f"resume={run}")  # finished: nothing left to do, as before
    assert result.returncode == 2 and "leaves nothing to do" in result.stderr
    assert f"python -m ppo_torchrl resume={run} runs" in str(stopped.value)  # what the stop said to run
    assert "marks the run finished" in str(stopped.value)


def test_a_run_stopped_midway_is_not_finished_early_by_a_smaller_budget(finished_run, tmp_path, capsys):
    """(A guard for the case above) only a run that trained its own budget is finished by resume=: one stopped at
    frame 512 of 1024 given collector.total_frames=256 still has nothing to do, and is left as it was."""
    import shutil

    run = copy_of(finished_run, tmp_path)
    shutil.copy(run / "checkpoints" / "frames_0000000512.pt", run / "checkpoints" / "last.pt")
    summary = json.loads((run / "summary.json").read_text())
    (run / "summary.json").write_text(json.dumps({**summary, "status": "interrupted", "frames": 512}))
    before = tree_digest(run)
    code, lines = refused([f"resume={run}", "collector.total_frames=256"], capsys)
    assert code == 2 and len(lines) == 1 and "leaves nothing to do" in lines[0], lines
    assert tree_digest(run) == before
