"""Issue 47, item 5: the data-safety property on a few fixed random sequences (benchmarks/data_safety.py; its long
modes run hundreds of run-dir step sequences, or the app's real commands). Each sequence mixes new runs, overwrites,
sweeps, trials, resumes, evaluations, exports and reports, cut by SIGINT or kill -9 at random instants, with a
user's files, symlinks and edited manifests; every user byte must stay, and every dir left must be usable or
explained. Below it, the write of an output that makes a kill at any instant safe."""

import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import data_safety  # noqa: E402

from conftest import launch  # noqa: E402

data_safety.LAUNCH = launch  # its commands as real processes, forked from the tests' launcher (tests/appserver.py)


@pytest.mark.parametrize("seed", [0, 6, 11, 18])
def test_no_sequence_of_commands_kills_and_edits_loses_a_user_byte(seed):
    assert data_safety.sequence(seed) == []


def test_an_output_is_listed_between_its_whole_temp_file_and_the_rename(tmp_path):
    """export/report/evaluate write through atomic_write_bytes(owner=run dir): a write that fails leaves the
    manifest and the old file as they were; one cut after the listing leaves a file the app owns (the next
    command may replace it), never one that reads as the user's."""
    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.lifecycle import Lifecycle

    run = tmp_path / "run"
    life = Lifecycle()
    life.claim(run)
    life.commit(run)
    manifest = (run / rundir.MANIFEST).read_bytes()

    def fails(f):
        f.write(b"half")
        raise RuntimeError("cut")

    with pytest.raises(RuntimeError):
        rundir.atomic_write_bytes(run / "policy.pt", fails, owner=run)
    assert (run / rundir.MANIFEST).read_bytes() == manifest and not list(run.glob("*.pt*")) and not list(run.glob(".*tmp"))

    rundir.intend(run, [run / "policy.pt", tmp_path / "elsewhere.pt"])  # the listing, then a kill mid-write:
    (run / "policy.pt").write_bytes(b"half")
    assert rundir.listed(run) == ["policy.pt"]
    rundir.check_replaceable(run, [run / "policy.pt"])  # the app's: replaced without a word
    rundir.atomic_write_bytes(run / "policy.pt", lambda f: f.write(b"whole"), owner=run)
    assert (run / "policy.pt").read_bytes() == b"whole"

    (run / "report.png").write_bytes(b"the user's")  # not listed: the user's, refused
    with pytest.raises(ConfigError):
        rundir.check_replaceable(run, [run / "report.png"])
    life.finish()


def test_the_apps_real_commands_cut_at_random_keep_every_user_byte():
    """The property on the app's own commands (issue 60 item 4): `python -m ppo_torchrl` runs, sweeps and trials,
    resume=, overwrite=true, evaluate, export and report on InvertedPendulum-v4, each cut by SIGINT or kill -9 at a
    random instant or let finish, among a user's edits; one short sequence here, many in the long mode
    (`python benchmarks/data_safety.py --real`). Then (issue 76 item 3) records, the Python API and a crafted
    checkpoint in one fixed order."""
    log = []
    assert data_safety.sequence(3, steps=5, real=True, log=log) == [], log
    assert any(" -> " in line for line in log), log  # real commands ran, not only a user's edits
    # issue 76 item 3: the records command, the Python API's train / evaluate_run / load and a crafted checkpoint, each
    # once (a user's edit before each), cut at random or let finish (the same start tree: this process's)
    new = ["records", "api_overwrite", "api_evaluate", "crafted", "api_load"]
    log = []
    assert data_safety.sequence(4, real=True, log=log, order=new) == [], log
    assert [kind for kind in new if any(f": {kind} " in line or f": {kind}" in line for line in log)] == new, log


def test_a_full_disk_or_a_kill_between_a_runs_write_and_its_listing_leaves_a_dir_overwrite_takes(tmp_path,
                                                                                                    monkeypatch, capsys):
    """Found by the long mode's full_disk and race cases: a full disk as a run's commit listed its start-up files
    left them unlisted and the old run in its sibling (no rollback); a kill -9 between a seed's summary.json and its
    listing left a dir that overwrite=true called someone else's ("it holds seed1/summary.json, which this app did
    not write"); a kill -9 as an overwrite wrote its manifest left a dir with the temp file alone, which the next
    overwrite=true moved aside again, naming that sibling, not the one with the run; a file-size limit (EFBIG) was
    an internal error, and an internal error with no writable temp dir ended in a traceback from the error path."""
    import errno

    from ppo_torchrl import errors

    from ppo_torchrl.run import rundir
    from ppo_torchrl.run.lifecycle import Lifecycle

    def fails(error):
        def call(*args, **kwargs):
            raise error
        return call

    run, life = tmp_path / "run", Lifecycle()
    life.claim(run)
    life.commit(run)
    life.finish()
    (run / "summary.json").write_text("{}")
    rundir.record(run)
    before = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*"))
    life = Lifecycle()
    life.claim(run, overwrite=True)
    (run / "config.yaml").write_text("seed: 1\n")
    with monkeypatch.context() as full:
        full.setattr(rundir, "record", fails(OSError(errno.ENOSPC, "No space left on device")))
        with pytest.raises(OSError):
            life.commit(run)
    life.finish()  # the claim is still pending: rolled back, the old run in its dir again
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == before
    seed = run / "seed1"  # a trial's seed killed after its summary.json and before its listing
    Lifecycle().claim(seed)
    (seed / "summary.json").write_text("{}")
    (seed / "config.yaml").write_text("seed: 1\n")
    rundir.check_new_dir(run, overwrite=True)  # the app's: overwrite=true takes the dir
    killed = tmp_path / "killed"  # kill -9 after the move-aside, as the new manifest was written
    (killed / f".{rundir.MANIFEST}.k9x2.tmp").parent.mkdir()
    (killed / f".{rundir.MANIFEST}.k9x2.tmp").write_text('{"app": "ppo_')
    shutil.copytree(run, tmp_path / "killed.replaced-20261128-120000")
    life = Lifecycle()
    life.claim(killed, overwrite=True)
    life.commit(killed)
    life.finish()
    assert len(list(tmp_path.glob("killed.replaced-*"))) == 1
    assert f"note: {tmp_path / 'killed.replaced-20261128-120000'} holds the run" in capsys.readouterr().err
    assert errors.message_of(OSError(errno.EFBIG, "File too large", "x.pt")).startswith(
        "error: a file reached the file size limit writing x.pt; raise the limit (ulimit -f)")
    assert errors.exit_code(OSError(errno.EFBIG, "File too large")) == 1
    monkeypatch.setattr(errors.tempfile, "mkstemp", fails(FileNotFoundError(2, "No usable temporary directory")))
    from ppo_torchrl.run.signals import ON_DISK

    monkeypatch.setattr(ON_DISK, "started", False)  # no run of this process (another test's in-process run may be)
    line = errors.message_of(KeyError("a bug"))
    assert line.startswith("error: internal error (KeyError: 'a bug')") and "no log file could be written" in line


def test_a_signal_after_a_command_is_done_is_ignored_not_a_traceback(monkeypatch):
    """The long mode's race case: a Ctrl-C landing as a finished command's Python shut down (joining its threads)
    printed Python's "Exception ignored ... KeyboardInterrupt" traceback after the command's last line. Each entry
    point, once its work is done (or its error line printed), ignores SIGINT and SIGTERM to the end."""
    import signal

    from ppo_torchrl import cli

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        cli.run(lambda argv: None)
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN and signal.getsignal(signal.SIGTERM) == signal.SIG_IGN
        for s in before:
            signal.signal(s, signal.SIG_DFL)
        with pytest.raises(SystemExit):  # the error path: its line, then the same
            cli.run(lambda argv: (_ for _ in ()).throw(ValueError("boom")))
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        for s, handler in before.items():
            signal.signal(s, handler)


def test_records_lists_what_it_writes_so_overwrite_takes_the_run(tmp_path, capsys):
    """Found by the property's records kind (issue 76 item 3): records wrote metrics.csv.xz into a run dir without
    listing it, so overwrite=true then refused the run ("it holds metrics.csv.xz, which this app did not write").
    The record is listed with its bytes' sha256, as evaluate's outputs are: overwrite=true takes the run; a prefix
    record the user put there is not replaced."""
    from ppo_torchrl import records
    from ppo_torchrl.run import rundir
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.run.lifecycle import Lifecycle

    run, life = tmp_path / "run", Lifecycle()
    life.claim(run)
    life.commit(run)
    (run / "metrics.csv").write_text("iteration,frames\n1,2048\n")
    rundir.record(run)
    life.finish()
    assert records.main([str(run / "metrics.csv")]) == 0
    assert "metrics.csv.xz" in rundir.listed(run) and rundir.foreign_files(run) == []
    rundir.check_new_dir(run, overwrite=True)  # the app's dir still: overwrite=true may take it
    users = tmp_path / "other"
    shutil.copytree(run, users)
    (users / "metrics.csv.xz").unlink()
    (users / "metrics.csv.xz").write_bytes(__import__("lzma").compress(b"iteration,frames\n"))  # the user's prefix
    with open(users / "metrics.csv", "a") as f:
        f.write("2,4096\n")
    with pytest.raises(ConfigError, match="is not a file this app wrote"):
        records.main([str(users / "metrics.csv")])
