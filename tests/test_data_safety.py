"""Issue 47, item 5: the data-safety property on a few fixed random sequences (benchmarks/data_safety.py; its long
modes run hundreds of run-dir step sequences, or the app's real commands). Each sequence mixes new runs, overwrites,
sweeps, trials, resumes, evaluations, exports and reports, cut by SIGINT or kill -9 at random instants, with a
user's files, symlinks and edited manifests; every user byte must stay, and every dir left must be usable or
explained. Below it, the write of an output that makes a kill at any instant safe."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import data_safety  # noqa: E402


@pytest.mark.parametrize("seed", [0, 6, 11, 18])
def test_no_sequence_of_commands_kills_and_edits_loses_a_user_byte(seed):
    assert data_safety.sequence(seed) == []


def test_an_output_is_listed_between_its_whole_temp_file_and_the_rename(tmp_path):
    """export/report/evaluate write through atomic_write_bytes(owner=run dir): a write that fails leaves the
    manifest and the old file as they were; one cut after the listing leaves a file the app owns (the next
    command may replace it), never one that reads as the user's."""
    from ppo_torchrl import rundir
    from ppo_torchrl.errors import ConfigError
    from ppo_torchrl.lifecycle import Lifecycle

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
    (`python benchmarks/data_safety.py --real`)."""
    log = []
    assert data_safety.sequence(3, steps=5, real=True, log=log) == [], log
    assert any(" -> " in line for line in log), log  # real commands ran, not only a user's edits
