"""Reliability round 5, second half (issue 60): readers hold a shared lock on the run dir they read (an overwrite
or a run refuses while one reads it, and a reader refuses while a run trains there); a run records the robot model
it trained on (a resume or an evaluate on a changed model is refused); a model without a floor is refused;
newcomer frictions (report.png's returns labelled, heights= with video=true, a first line before heavy imports,
progress lines as often as the README says)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from conftest import ROOT, App, compose_config, run_app
from ppo_torchrl import evaluate, export, report
from test_bad_input import finished_run, refused, tree_digest  # noqa: F401  (the module's finished run)
from test_reliability_round3 import RUN, copy_of
from test_reliability_round5 import ran

GO1 = ROOT / "ppo_torchrl" / "assets" / "menagerie" / "unitree_go1"


def start(module, *args):
    """An entry point in a process of its own (the second process of a test), its output in a pipe."""
    return App(args, module=module, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def wait_for_lock(directory, kind, process, timeout=180):
    """Until `process` holds the dir's flock of `kind` (READ: shared, WRITE: exclusive), per /proc/locks."""
    st = os.stat(directory)
    dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for line in open("/proc/locks").read().splitlines():
            parts = line.split()
            if "FLOCK" in parts and "->" not in parts and parts[-3] == dev and parts[-4] == str(process.pid):
                if parts[-5] == kind:
                    return
        if process.poll() is not None:
            pytest.fail(f"{process.args} ended ({process.returncode}) without holding {directory}: "
                        f"{process.stderr.read()[-2000:]}")
        time.sleep(0.1)
    pytest.fail(f"{process.args} never held {directory}'s lock ({kind}) in {timeout} s")


def stop(process):
    """End a process this test started: SIGINT (a run checkpoints and ends), then SIGKILL after 60 s."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(60)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    process.stderr.close()


# ---------------------------------------------------------------- 1. readers hold a shared lock

def test_an_overwrite_refuses_while_an_evaluate_reads_the_run(finished_run, tmp_path, capsys):
    """An evaluate of <dir> runs (a process of its own); `hydra.run.dir=<dir> overwrite=true` starting then would
    have put the old policy's eval.json in the new run's dir: it is one line naming the reader's pid, and the dir is
    as it was. Another reader (export) runs beside it."""
    run = copy_of(finished_run, tmp_path)
    reader = start("ppo_torchrl.evaluate", f"run={run}", "episodes=1000000")
    try:
        wait_for_lock(run, "READ", reader)
        before = tree_digest(run)
        code, lines = refused([*RUN, f"hydra.run.dir={run}", "overwrite=true"], capsys)  # a check: nothing kept
        assert code == 2 and len(lines) == 1, lines
        assert f"is in use by pid {reader.pid}" in lines[0] and "reading it" in lines[0], lines
        assert tree_digest(run) == before and not list(tmp_path.glob("run.replaced-*"))
        code, lines = ran(export.main, [f"run={run}"], capsys)
        assert code == 0, lines
    finally:
        stop(reader)


def test_evaluate_export_and_report_refuse_while_a_run_trains_there(finished_run, tmp_path, capsys):
    """A resume trains in <dir> (a process of its own): evaluate, export and report of <dir> are one line each,
    naming the writer's pid, exit 2 (they read checkpoints and wrote beside a run that writes them)."""
    run = copy_of(finished_run, tmp_path)
    writer = start("ppo_torchrl", f"resume={run}", "collector.total_frames=100000000")
    try:
        wait_for_lock(run, "WRITE", writer)
        for main, args in ((evaluate.main, [f"run={run}", "episodes=1"]), (export.main, [f"run={run}"]),
                           (report.main, [str(run)])):
            code, lines = ran(main, args, capsys)
            assert code == 2 and len(lines) == 1, (main.__module__, lines)
            assert f"is in use by pid {writer.pid}, which is writing there" in lines[0], lines
    finally:
        stop(writer)


# ---------------------------------------------------------------- 2. a run records what its robot model was

@pytest.fixture(scope="module")
def go1_run(tmp_path_factory):
    """A tiny legged run on a copy of the shipped Go1 (its scene.xml including go1.xml), via the CLI."""
    import shutil

    root = tmp_path_factory.mktemp("go1")
    shutil.copytree(GO1, root / "go1")
    run = root / "run"
    done = run_app(["env=legged", f"env.xml_file={root / 'go1' / 'scene.xml'}", *RUN[1:], f"hydra.run.dir={run}"],
                   timeout=600, env=dict(os.environ))
    assert done.returncode == 0, done.stderr[-2000:]
    return run, root / "go1" / "go1.xml"


def test_resume_and_evaluate_refuse_a_robot_model_changed_since_the_run(go1_run, capsys):
    """The copy's trunk gets 1 kg more after the run: resume= and evaluate are one line naming env.xml_file= and
    overwrite, exit 2, and the run is as it was; with the model put back both go on."""
    run, model = go1_run
    original = model.read_text()
    assert original.count('mass="5.204"') == 1  # the trunk's
    model.write_text(original.replace('mass="5.204"', 'mass="6.204"'))
    try:
        before = tree_digest(run)
        code, lines = refused([f"resume={run}", "collector.total_frames=1024"], capsys)
        assert code == 2 and len(lines) == 1, lines
        assert "env.xml_file=" in lines[0] and "overwrite=true" in lines[0] and "not the one this run trained on" in lines[0]
        code, lines = ran(evaluate.main, [f"run={run}", "checkpoint=last", "episodes=1"], capsys)
        assert code == 2 and len(lines) == 1 and "env.xml_file=" in lines[0] and "overwrite" in lines[0], lines
        assert tree_digest(run) == before
    finally:
        model.write_text(original)
    from ppo_torchrl.run.lifecycle import Lifecycle

    life = Lifecycle()
    try:  # the model it trained on: accepted
        assert life.resume(str(run), ["collector.total_frames=1024"]).run_dir == run
    finally:
        life.finish()


def test_a_checkpoint_that_recorded_no_model_is_not_checked(tiny_cfg):
    """A run of an earlier version (no `model` in its checkpoints), or of a Gymnasium env: accepted silently."""
    from ppo_torchrl.run.model_record import check_model

    cfg = compose_config(["env=legged", f"env.xml_file={GO1 / 'scene.xml'}"])
    check_model({"frames": 256}, cfg.env, "resume=old")
    check_model({"model": None}, tiny_cfg().env, "resume=old")


# ---------------------------------------------------------------- 3. a model without a floor

@pytest.mark.parametrize("beside", [True, False])
def test_a_robot_file_without_a_floor_is_refused_naming_its_scene(tmp_path, capsys, beside):
    """Menagerie's go1.xml alone has no floor: the robot fell through the world for the whole run (exit 0). One line,
    naming the scene.xml beside it when there is one (else how to add a floor); nothing written."""
    import shutil

    folder = tmp_path / "go1"
    folder.mkdir()
    shutil.copy(GO1 / "go1.xml", folder / "go1.xml")
    if beside:
        shutil.copy(GO1 / "scene.xml", folder / "scene.xml")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    code, lines = refused(["env=legged", f"env.xml_file={folder / 'go1.xml'}", f"hydra.run.dir={tmp_path / 'run'}"],
                          capsys)
    assert code == 2 and len(lines) == 1 and "has no floor" in lines[0], lines
    assert (f"env.xml_file={folder / 'scene.xml'}" in lines[0]) == beside and ('type="plane"' in lines[0]) != beside
    assert sorted(p.name for p in tmp_path.rglob("*")) == before


# ---------------------------------------------------------------- 4. newcomer frictions

def test_report_tells_curriculum_training_episodes_from_the_eval(finished_run, tmp_path):
    """A step run on a curriculum: report.png's train curves (episodes on the curriculum's steps, ending early at a
    fall) and eval points (one fixed step) share an axis; their legend says what each is."""
    from omegaconf import OmegaConf

    run = copy_of(finished_run, tmp_path)
    cfg = OmegaConf.load(run / "config.yaml")
    OmegaConf.update(cfg, "env.terrain", {"curriculum": True, "step_height": None, "step_height_range": [0.0, 0.2],
                                          "eval_step_height": 0.1}, force_add=True)
    (run / "config.yaml").write_text(OmegaConf.to_yaml(cfg))
    import matplotlib.pyplot as plt

    fig = report.run_figure(run)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    plt.close(fig)
    train = [label for label in labels if label.startswith("train")]
    assert len(train) == 2 and all("curriculum" in label and "end early" in label for label in train), labels
    assert any(label.startswith("eval") and "fixed step of 10 cm" in label for label in labels), labels
    plain = report.run_figure(finished_run)  # a run without a step: the labels as they were
    assert not any("curriculum" in t.get_text() for t in plain.axes[0].get_legend().get_texts())
    plt.close(plain)


def test_heights_with_video_says_how_to_film_a_height(finished_run, capsys):
    """evaluate heights=... video=true: one line that says how to film a height (a command per height)."""
    code, lines = ran(evaluate.main, [f"run={finished_run}", "heights=0,0.1", "video=true"], capsys)
    assert code == 2 and len(lines) == 1, lines
    assert "env.terrain.step_height=<m> video=true" in lines[0], lines


@pytest.mark.parametrize("module", ["ppo_torchrl.evaluate", "ppo_torchrl.export"])
def test_help_comes_before_the_heavy_imports(module):
    """`evaluate --help` took 6-10 s (torch, torchrl imported first): the page now comes before them."""
    began = time.monotonic()
    done = subprocess.run([sys.executable, "-X", "importtime", "-m", module, "--help"], cwd=ROOT, capture_output=True,
                          text=True, timeout=120)
    took = time.monotonic() - began
    assert done.returncode == 0 and done.stdout.startswith(f"usage: python -m {module} run=<run dir>"), done.stdout
    imported = {line.split("|")[-1].strip() for line in done.stderr.splitlines() if line.startswith("import time:")}
    assert not {"torch", "torchrl", "numpy"} & imported and took < 5, (took, sorted(imported)[:20])


def test_progress_lines_come_at_most_print_every_s_apart(monkeypatch, capsys):
    """Plain progress lines (not a terminal) every <= logger.print_every_s (10 s), as the README says: they came
    at the first iteration after 10 s: 10.4 s apart with 1.3 s iterations."""
    from ppo_torchrl.run import loggers

    clock = [0.0]
    monkeypatch.setattr(loggers.time, "perf_counter", lambda: clock[0])
    progress = loggers.Progress(100 * 2048, 0, 10.0, tty=False)
    printed = []
    for i in range(1, 101):
        clock[0] = 1.3 * i
        progress.update({"frames": 2048 * i, "sps": 1600.0, "train/return_last100": 1.0}, 2048, force=i == 100)
        if capsys.readouterr().err:
            printed.append(clock[0])
    gaps = [b - a for a, b in zip(printed, printed[1:])]
    assert gaps and max(gaps) <= 10.0 and min(gaps[:-1]) >= 5.0, gaps


# ---------------------------------------------------------------- a kill as an overwrite began

def test_a_dir_left_with_only_the_manifests_temp_file_names_the_run_moved_aside(finished_run, tmp_path, capsys):
    """kill -9 just after overwrite=true moved the old run aside, as the new manifest was being written: the dir
    held only that temp file. resume= said it needs checkpoints/last.pt, and a new run or an overwrite refused the
    temp file as not the app's (5 of 5 tries). Now resume= and evaluate name the sibling that holds the run, a new
    run takes the dir, and its start names the sibling."""
    from ppo_torchrl.run.lifecycle import Lifecycle

    run = tmp_path / "run"
    aside = copy_of(finished_run, tmp_path).rename(tmp_path / "run.replaced-20261128-120000")
    run.mkdir()
    (run / "..ppo_torchrl.json.k9x2_q.tmp").write_text('{"app": "ppo_')  # what the kill left
    code, lines = refused([f"resume={run}", "collector.total_frames=1024"], capsys)
    assert code == 2 and len(lines) == 1 and f"resume={aside}" in lines[0], lines
    code, lines = ran(evaluate.main, [f"run={run}", "episodes=1"], capsys)
    assert code == 2 and len(lines) == 1 and f"run={aside}" in lines[0], lines
    life = Lifecycle()
    try:
        life.new_run(run)  # the leftover is the app's: a new run may start there (overwrite=true too)
        life.commit(run)
    finally:
        life.finish()
    note = capsys.readouterr().err
    assert f"note: {aside} holds the run an earlier overwrite=true moved out of {run}" in note, note
    assert (aside / "checkpoints" / "last.pt").is_file()  # the old run, untouched


def test_a_full_disk_as_an_overwrite_begins_puts_the_old_run_back(finished_run, tmp_path, monkeypatch):
    """A full disk as overwrite=true wrote the new run's manifest left the old run in its sibling, which no later
    command named: the claim now rolls back, the old run in its own dir again and no sibling left."""
    import errno

    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.lifecycle import Lifecycle

    run = copy_of(finished_run, tmp_path)
    before = tree_digest(run)
    write = rundir.atomic_write_json

    def full(path, data, owner=None):
        if path.name == rundir.MANIFEST and path.parent == run:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return write(path, data, owner)

    monkeypatch.setattr(rundir, "atomic_write_json", full)
    life = Lifecycle()
    with pytest.raises(OSError, match="No space left"):
        life.claim(run, overwrite=True)
    life.finish()
    assert tree_digest(run) == before and not list(tmp_path.glob("*.replaced-*"))
    with pytest.raises(ConfigError, match="already holds a run"):  # and it is still the run it was
        Lifecycle().claim(run)


def test_a_trial_of_a_sweep_killed_in_a_seed_leaves_a_sweep_the_next_command_takes(tmp_path):
    """kill -9 in seed 7 of an optuna_seeds trial (before its first checkpoint): the same command, with or without
    overwrite=true, called the sweep's files not the app's (the trial's manifest answered for its seed's files),
    and resume=<sweep>/0 said its seeds were all finished. Now the sweep dir is a sweep (overwrite=true replaces
    it), and resume names the stopped seed and the command that runs the study on."""
    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.lifecycle import Lifecycle

    sweep, write = tmp_path / "sweep", lambda path, text: rundir.atomic_write_bytes(path, lambda f: f.write(text))
    life = Lifecycle()
    life.sweep(sweep)
    trial = sweep / "0"
    life.claim(trial, what="job")
    write(trial / ".hydra" / "config.yaml", b"{}\n")
    life.commit(trial)
    for seed, status in (("seed6", b'{"status": "finished"}\n'), ("seed7", None)):
        life.claim(trial / seed)
        write(trial / seed / "config.yaml", b"seed: 1\n")
        write(trial / seed / "metrics.csv", b"frames\n")
        life.commit(trial / seed)
        if status:
            write(trial / seed / "summary.json", status)
            rundir.record(trial / seed)
            write(trial / "trial.json", b"{}\n")
            rundir.record(trial)
    life.finish()  # then the kill: seed7 has no checkpoint, no summary
    with pytest.raises(ConfigError, match="already holds a sweep.*overwrite=true"):
        rundir.check_new_dir(sweep, overwrite=False, what="sweep")
    rundir.check_new_dir(sweep, overwrite=True, what="sweep")  # replaceable
    with pytest.raises(ConfigError, match="its seed7 stopped before its first checkpoint.*the sweep's command with "
                                          "overwrite=true"):
        Lifecycle().resume(str(trial), [])


def test_too_few_open_files_for_the_workers_is_one_line_before_anything_starts(tmp_path):
    """`ulimit -n 48` and collector.workers=2: each worker's queue printed a traceback, an internal error came after a
    minute (its error.log then deleted by the rollback) and the sweep ran on. Now: one line, exit 1, nothing written."""
    command = (f"ulimit -n 48; exec {sys.executable} -m ppo_torchrl -m env=InvertedPendulum-v4 seed=1,2 "
               f"collector.workers=2 collector.total_frames=4096 hydra.sweep.dir={tmp_path / 'sweep'}")
    done = subprocess.run(["bash", "-c", command], cwd=ROOT, capture_output=True, text=True, timeout=120)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 1 and len(lines) == 1, lines
    assert "collector.workers=2 needs about 128 open files" in lines[0] and "ulimit -n" in lines[0], lines
    assert not (tmp_path / "sweep").exists()


def test_an_internal_error_before_a_run_started_logs_where_the_rollback_leaves_it(tmp_path, monkeypatch, capsys):
    """The error line named <job dir>/error.log, which the rollback of the refused job then deleted: a run not yet
    started (its dir is rolled back) logs to a temp file the line names."""
    import re

    from ppo_torchrl.errors import guarded
    from ppo_torchrl.run.signals import ON_DISK

    monkeypatch.setattr(ON_DISK, "run_dir", tmp_path)
    monkeypatch.setattr(ON_DISK, "started", False)

    def buggy():
        raise KeyError("a bug")

    with pytest.raises(SystemExit):
        guarded(buggy)
    log = re.search(r"traceback in (\S+)$", capsys.readouterr().err.strip()).group(1)
    assert not (tmp_path / "error.log").exists() and "raise KeyError" in open(log).read()


def test_on_a_terminal_the_first_line_comes_at_once_and_a_refusal_stays_one_line(tmp_path):
    """Every entry point was silent 5-10 s before its first line (the imports). On a terminal a status line now
    comes at once; the command's first line erases it, so a refusal still reads as its one line."""
    import pty
    import select

    began = time.monotonic()
    pid, fd = pty.fork()
    if pid == 0:  # the child: the command on a terminal
        os.chdir(ROOT)
        os.execv(sys.executable, [sys.executable, "-m", "ppo_torchrl", "env=InvertedPendulum-v4", "optim.lr=-1",
                                  f"hydra.run.dir={tmp_path / 'run'}"])
    out, first = b"", None
    while select.select([fd], [], [], 120)[0]:
        try:
            chunk = os.read(fd, 4096)
        except OSError:  # the terminal closed: the command ended
            break
        if not chunk:
            break
        first = time.monotonic() - began if first is None else first
        out += chunk
    _, status = os.waitpid(pid, 0)
    shown = out.decode().split("\x1b[K")[-1]  # what the terminal shows once the status line is erased
    assert first is not None and first < 2.0, first
    assert os.waitstatus_to_exitcode(status) == 2 and shown.strip() == "error: optim.lr=-1.0 must be > 0", out
    assert not (tmp_path / "run").exists()


def test_a_record_checkpoint_evaluates_and_inits_but_says_it_cannot_resume(finished_run, tmp_path, capsys):
    """A reported row keeps its final checkpoint in results/ (a 40 MiB tree): `python -m ppo_torchrl.records
    <last.pt>` drops the optimizer's state (two thirds of a robot's 0.65 MB). It evaluates as before; resume= says
    what it is and what to run instead, in one line; init_from= trains on from it."""
    import ppo_torchrl
    from ppo_torchrl import records

    run = copy_of(finished_run, tmp_path)
    last = run / "checkpoints" / "last.pt"
    before, size = ppo_torchrl.evaluate_run(run, episodes=2, checkpoint="last"), last.stat().st_size
    assert records.main([str(last)]) == 0
    assert last.stat().st_size < size
    after = ppo_torchrl.evaluate_run(run, episodes=2, checkpoint="last")
    assert after["returns"] == before["returns"]
    capsys.readouterr()
    code, lines = refused([f"resume={run}", "collector.total_frames=4096"], capsys)
    assert code == 2 and len(lines) == 1 and "record checkpoint" in lines[0] and f"init_from={run}" in lines[0], lines
    assert records.main([str(last)]) == 0  # again: the same record
    tiny = ["env=InvertedPendulum-v4", "collector.total_frames=256", "collector.frames_per_batch=256", "loss.epochs=1",
            "eval.every_frames=0", "eval.final_episodes=1", "eval.video=false", "logger=none", f"init_from={last}"]
    assert ppo_torchrl.train(tiny, run_dir=tmp_path / "on").summary["frames"] == 256


def test_a_run_killed_before_its_first_checkpoint_is_not_offered_resume(finished_run, tmp_path):
    """kill -9 in a run's first minute leaves a run dir with no checkpoints/last.pt: the same command said "continue
    it with resume=<dir>", and resume then said the dir needs checkpoints/last.pt. Now it says there is nothing to
    resume and offers the two commands that work."""
    import shutil

    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.lifecycle import Lifecycle

    run = copy_of(finished_run, tmp_path)
    shutil.rmtree(run / "checkpoints")
    with pytest.raises(ConfigError, match="no checkpoints/last.pt .nothing to resume.") as refused_new:
        Lifecycle().claim(run)
    assert "resume=" not in str(refused_new.value) and "overwrite=true" in str(refused_new.value)
    with pytest.raises(ConfigError, match="needs checkpoints/last.pt"):  # and resume says the same
        Lifecycle().resume(str(run), [])
