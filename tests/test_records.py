"""Issue 61 item 1: results/ keeps records, and the repository stays small. The check CI runs (.ci/records_check.py)
on this checkout and on a planted 2 MB file; the records' compressed form read as the plain one."""

from __future__ import annotations

import importlib.util
import lzma
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

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


def test_the_records_command_refuses_bad_input_in_one_line(tmp_path):
    out = subprocess.run([sys.executable, "-m", "ppo_torchrl.records", str(tmp_path / "missing.csv")],
                         capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 2 and out.stderr.strip().count("\n") == 0 and out.stderr.startswith("error: ")
