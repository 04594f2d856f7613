"""The data-safety property (issue 47, item 5): random sequences of the app's run-dir commands, each cut by a
random SIGINT or kill -9 or let finish, on a tree that holds the user's files, symlinks and edited manifests.
After every step each user byte is still there (its hash, at its path or in the sibling an overwrite moved its
dir to), and at the end every run dir is usable or explained (a new command there works or is one `error:`
line, never a traceback).

The commands are the app's own run-dir steps, in a fresh process each, through `ppo_torchrl.rundir` as the
entry points call it: a new run and `overwrite=true` (claim, Hydra's start-up files, the first listing,
commit, checkpoints and summary written atomically and listed), `resume=` (claim, more checkpoints) and
`evaluate` (check, eval.json, listing). Training itself is left out: it writes only through these steps, and
a sequence takes seconds instead of minutes.

    python benchmarks/data_safety.py [--sequences 200] [--seed 0]     # the long mode
tests/test_data_safety.py runs a few fixed sequences in make test.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = ("r0", "r1", "r2")

# One app command in its own process: argv = kind, run dir, a pause (s) between its steps (where kills land).
COMMAND = r'''
import sys, time, json
from pathlib import Path
from ppo_torchrl import rundir
from ppo_torchrl.errors import ConfigError
kind, d, pause = sys.argv[1], Path(sys.argv[2]), float(sys.argv[3])
print("ready", flush=True)  # imports done: the harness's signal lands in the command's steps
def step(): time.sleep(pause)
try:
    if kind in ("new", "overwrite"):
        rundir.claim(d, overwrite=kind == "overwrite")
        step()
        for name in ("config", "hydra", "overrides"):
            rundir.atomic_write_bytes(d / ".hydra" / f"{name}.yaml", lambda f: f.write(b"{}\n"))
        step()
        rundir.atomic_write_bytes(d / "config.yaml", lambda f: f.write(b"seed: 1\n"))
        rundir.commit(d)
        for frames in (256, 512):
            step()
            rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(b"ckpt%d" % frames))
            rundir.atomic_write_json(d / "summary.json", {"status": "running", "frames": frames})
            rundir.record(d)
        rundir.atomic_write_json(d / "summary.json", {"status": "finished", "frames": 512})
        rundir.record(d)
    elif kind == "resume":
        if not (d / "checkpoints" / "last.pt").is_file():
            raise ConfigError(f"resume={d}: not a run dir with a checkpoint")
        rundir.claim(d, resume=True)
        step()
        rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(b"ckpt768"))
        rundir.record(d)
    elif kind == "evaluate":
        if not d.is_dir():
            raise ConfigError(f"run={d}: no such run dir")
        out = [d / "eval" / "eval.json"]
        rundir.check_replaceable(d, out)
        step()
        rundir.atomic_write_json(out[0], {"return_mean": 1.0})
        rundir.record(d, out)
except ConfigError as exc:
    rundir.finish()
    print(f"error: {exc}", file=sys.stderr)
    sys.exit(2)
except KeyboardInterrupt:
    rundir.finish()
    sys.exit(130)
rundir.finish()
'''


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


class Tree:
    """A temp tree: run dirs at its top, the user's folder beside them; the user's files and their hashes."""

    def __init__(self, root: Path, rng: random.Random):
        self.root, self.rng = root, rng
        self.user = root / "user"
        self.user.mkdir()
        self.files: dict = {}  # path relative to root -> hash
        self.add_user_file(self.user / "keep.txt")

    def add_user_file(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(os.urandom(16))
        self.files[path.relative_to(self.root).as_posix()] = digest(path)

    def user_step(self) -> str:
        """Something a user does by hand to the tree; returns what, for the failure report."""
        run = self.root / self.rng.choice(RUNS)
        kind = self.rng.choice(["file", "eval_file", "symlink", "manifest", "replaced_file"])
        if not run.is_dir():
            return "nothing (no dir)"
        if kind == "file":
            self.add_user_file(run / "notes" / f"n{self.rng.randrange(1000)}.txt")
        elif kind == "eval_file":
            self.add_user_file(run / "eval" / "paper_numbers.csv")
        elif kind == "replaced_file":
            self.add_user_file(run / ".replaced" / "config.yaml")
        elif kind == "symlink" and not (run / ".replaced").exists():
            (run / ".replaced").symlink_to(self.user)
        elif kind == "manifest" and (run / ".ppo_torchrl.json").is_file():
            data = json.loads((run / ".ppo_torchrl.json").read_text())
            data["files"] = list(data.get("files", [])) + ["../user/keep.txt", str(self.user / "keep.txt"), 7]
            (run / ".ppo_torchrl.json").write_text(json.dumps(data))
        return f"{kind} in {run.name}"

    def lost(self) -> list:
        """The user's files not found whole at their path nor where an overwrite moved their dir."""
        missing = []
        for rel, want in self.files.items():
            top, _, rest = rel.partition("/")
            places = [self.root / rel] + ([p / rest for p in self.root.glob(f"{top}.replaced-*")] if rest else [])
            if not any(p.is_file() and not p.is_symlink() and digest(p) == want for p in places):
                missing.append(rel)
        return missing


def app(kind: str, run: Path, rng: random.Random) -> tuple:
    """One app command, cut by SIGINT or kill -9 at a random instant, or let finish: (how it ended, stderr)."""
    pause = rng.choice([0.0, 0.01, 0.03])
    proc = subprocess.Popen([sys.executable, "-c", COMMAND, kind, str(run), str(pause)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    cut = rng.choice([None, None, signal.SIGINT, signal.SIGKILL])
    proc.stdout.readline()  # "ready" (or nothing: it ended)
    if cut is not None:
        time.sleep(rng.uniform(0.0, 0.3))
        if proc.poll() is None:
            proc.send_signal(cut)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, err


def explained(code: int, err: str) -> bool:
    """The command worked, was cut by its signal (here a SIGINT that lands in its error path ends it by the
    signal), or said why in one `error:` line (never a traceback)."""
    lines = [line for line in err.splitlines() if line.strip()]
    return code in (0, 130, -signal.SIGINT, -signal.SIGKILL) or (code == 2 and len(lines) == 1 and lines[0].startswith("error:"))


def sequence(seed: int, steps: int = 10) -> list:
    """One random sequence; returns its failures (empty: every user byte kept, every dir usable or explained)."""
    rng = random.Random(seed)
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        tree = Tree(Path(tmp), rng)
        for i in range(steps):
            if rng.random() < 0.35:
                what = "user: " + tree.user_step()
            else:
                kind, run = rng.choice(["new", "overwrite", "overwrite", "resume", "evaluate"]), rng.choice(RUNS)
                code, err = app(kind, tree.root / run, rng)
                what = f"{kind} {run} -> {code}"
                if not explained(code, err):
                    failures.append(f"seed {seed} step {i} {what}: {err.strip()[-300:]}")
            lost = tree.lost()
            if lost:
                failures.append(f"seed {seed} step {i} ({what}): user files lost: {lost}")
                break
        for run in RUNS:  # every dir left: a new command there works or is explained
            if (tree.root / run).exists():
                code, err = _plain(tree.root / run)
                if not explained(code, err):
                    failures.append(f"seed {seed} end: {run} not usable: {err.strip()[-300:]}")
        lost = tree.lost()
        if lost:
            failures.append(f"seed {seed} end: user files lost: {lost}")
    return failures


def _plain(run: Path) -> tuple:
    """overwrite=true in `run`, let finish."""
    proc = subprocess.run([sys.executable, "-c", COMMAND, "overwrite", str(run), "0"], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    return proc.returncode, proc.stderr


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    start, failures = time.time(), []
    for k in range(args.sequences):
        failures += sequence(args.seed * 100_000 + k)
    print(f"{args.sequences} sequences (seeds {args.seed * 100_000}..{args.seed * 100_000 + args.sequences - 1}) in "
          f"{time.time() - start:.0f} s: {len(failures)} failures")
    for failure in failures:
        print(failure)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
