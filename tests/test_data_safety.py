"""Issue 47, item 5: the data-safety property on a few fixed random sequences (benchmarks/data_safety.py; its long
mode runs hundreds). Each sequence mixes new runs, overwrites, resumes and evaluations, cut by SIGINT or kill -9 at
random instants, with a user's files, symlinks and edited manifests; every user byte must stay, and every dir
left must be usable or explained."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import data_safety  # noqa: E402


@pytest.mark.parametrize("seed", [0, 6, 11, 18])
def test_no_sequence_of_commands_kills_and_edits_loses_a_user_byte(seed):
    assert data_safety.sequence(seed) == []
