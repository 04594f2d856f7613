"""Issue 61 item 1: results/ keeps records, and the repository stays small. The check CI runs (.ci/records_check.py)
on this checkout and on a planted 2 MB file; the records' compressed form read as the plain one."""

from __future__ import annotations

import importlib.util
import lzma
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import run_app
from ppo_torchrl import records
from ppo_torchrl.report import read_metrics

ROOT = Path(__file__).resolve().parents[1]


def records_check():
    spec = importlib.util.spec_from_file_location("records_check", ROOT / ".ci" / "records_check.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def git(repo: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_this_checkout_passes_the_records_check():
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    assert records_check().findings(ROOT) == []


def test_a_planted_2mb_file_fails_the_check_until_it_is_allow_listed(tmp_path, monkeypatch):
    check = records_check()
    git(tmp_path, "init", "-q")
    (tmp_path / ".ci").mkdir()
    (tmp_path / ".ci" / "large_files.txt").write_text("# none\n")
    (tmp_path / "small.txt").write_text("a record\n")
    git(tmp_path, "add", ".")
    assert check.findings(tmp_path) == []
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "big.pt").write_bytes(b"\0" * 2_000_000)
    git(tmp_path, "add", "results/big.pt")
    found = check.findings(tmp_path)
    assert len(found) == 1 and found[0].startswith("results/big.pt is 2.0 MB")
    assert subprocess.run([sys.executable, str(ROOT / ".ci" / "records_check.py"), str(tmp_path)],
                          capture_output=True).returncode == 1
    (tmp_path / ".ci" / "large_files.txt").write_text("results/big.pt  # why\n")
    assert check.findings(tmp_path) == []
    for name in ("results/row/metrics.csv", "results/row/checkpoints/best.pt"):  # a training row's working files
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("working\n")
        git(tmp_path, "add", name)
        assert check.findings(tmp_path) == [f"{name} is a training row's working file: commit its record instead "
                                            "(the curve as metrics.csv.xz: `xz -9`, then benchmarks/thin_metrics.py "
                                            "once the row is finished; checkpoints/last.pt)"]
        git(tmp_path, "rm", "-q", "--cached", name)
    monkeypatch.setattr(check, "TREE_LIMIT", 1_000_000)  # the tree's budget
    assert check.findings(tmp_path)[-1].startswith("the tracked tree is 1.9 MiB")


def test_a_compressed_metrics_record_reads_as_the_plain_one(tmp_path):
    plain = tmp_path / "run" / "metrics.csv"
    plain.parent.mkdir()
    plain.write_text("iteration,frames,train/episode_return\n1,2048,3.5\n2,4096,\n")
    packed = records.compress(plain)
    assert packed.name == "metrics.csv.xz" and plain.read_text().startswith("iteration")  # the plain one stays
    kept = tmp_path / "record" / "metrics.csv"
    kept.parent.mkdir()
    shutil.copy(packed, kept.parent / packed.name)
    a, b = read_metrics(plain), read_metrics(kept)
    assert a.keys() == b.keys() and a["frames"] == b["frames"] == [2048.0, 4096.0]
    assert records.has_record(kept) and not kept.exists()
    assert records.compress(plain) == packed  # the same record again: nothing changes
    with open(plain, "a") as f:  # the run resumed and logged on: the mid-run record is brought up to date
        f.write("3,6144,4.0\n")
    assert records.compress(plain) == packed
    assert lzma.decompress(packed.read_bytes()) == plain.read_bytes()
    plain.write_text("iteration,frames\n1,2048\n")
    with pytest.raises(FileExistsError):  # another text: the record there is not replaced
        records.compress(plain)


def test_a_resume_keeps_the_bytes_of_the_rows_before_its_checkpoint(tmp_path):
    """truncate_logs (resume) drops the rows past the checkpoint and keeps the others byte for byte: the csv
    module's \\r\\n stays, so the log stays a prefix of itself and a mid-run record of it can be brought up to date."""
    from ppo_torchrl.run.loggers import MetricsFile, truncate_logs

    log = MetricsFile(tmp_path / "metrics.csv", ["iteration", "frames", "x"])
    for i in range(1, 5):
        log.write({"iteration": i, "frames": 2048 * i, "x": 0.5 * i})
    log.close()
    before = (tmp_path / "metrics.csv").read_bytes()
    assert b"\r\n" in before
    records.compress(tmp_path / "metrics.csv")
    truncate_logs(tmp_path, 4096)
    after = (tmp_path / "metrics.csv").read_bytes()
    assert before.startswith(after) and after.count(b"\r\n") == 3  # header and two rows, as written
    log = MetricsFile(tmp_path / "metrics.csv", ["iteration", "frames", "x"], append=True)
    for i in range(3, 7):
        log.write({"iteration": i, "frames": 2048 * i, "x": 0.5 * i})
    log.close()
    (tmp_path / "metrics.csv.xz").unlink()
    truncate_logs(tmp_path, 8192)
    records.compress(tmp_path / "metrics.csv")  # a record of the log at 4 rows ...
    log = MetricsFile(tmp_path / "metrics.csv", ["iteration", "frames", "x"], append=True)
    log.write({"iteration": 5, "frames": 10240, "x": 2.5})
    log.close()
    truncate_logs(tmp_path, 10240)  # ... and a resume at 5: the record is a prefix, brought up to date
    packed = records.compress(tmp_path / "metrics.csv")
    assert lzma.decompress(packed.read_bytes()) == (tmp_path / "metrics.csv").read_bytes()


def test_the_records_command_refuses_bad_input_in_one_line(tmp_path):
    out = run_app([str(tmp_path / "missing.csv")], module="ppo_torchrl.records", env=dict(os.environ))
    assert out.returncode == 2 and out.stderr.strip().count("\n") == 0 and out.stderr.startswith("error: ")


def test_code_under_results_fails_the_check(tmp_path):
    """Issue 76 item 4: results/ holds records, not code (seven scripts there imported the package); a tracked .py
    under results/ is a finding, one beside it in benchmarks/ is not."""
    check = records_check()
    git(tmp_path, "init", "-q")
    for name in ("results/robots/run/plot.py", "benchmarks/plot.py", "results/robots/run/table.md"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text("import ppo_torchrl\n")
    git(tmp_path, "add", ".")
    found = check.findings(tmp_path)
    assert len(found) == 1 and found[0].startswith("results/robots/run/plot.py is code under results/"), found
