"""The data-safety property (issue 47, item 5): random sequences of the app's commands (train, sweep, trial,
resume, overwrite, evaluate, report, export), each cut by a random SIGINT or kill -9 or let finish, on a tree
that holds the user's files (beside the app's, and where the app writes its outputs), symlinks and edited
manifests. Each sequence starts from r0 a finished run, r1 a finished sweep of two jobs and r2 a finished trial
of two seeds; commands that read a run also go to a sweep's job or a trial's seed. After every step each user
byte is still there (its hash, at its path or in the sibling an overwrite moved its dir to), and at the end
every dir is usable or explained (`overwrite=true` there works or is one `error:` line, never a traceback).

Two modes, one property:
- run-dir steps (default): each command is a fresh process that makes the entry points' `ppo_torchrl.rundir`
  calls in their order (claims, Hydra's start-up files, commits, atomic checkpoints and summaries, listings,
  outputs written through `owner=`), with pauses where the kills land; milliseconds a step.
- `--real`: the app's own commands (`python -m ppo_torchrl ...`, `-m` sweeps, `trial_seeds`, `resume=`,
  `overwrite=true`, `ppo_torchrl.evaluate`, `.export`, `.report`) on InvertedPendulum-v4 with 2,048 frames,
  cut at a random instant in their first 15 s (SIGINT to the process group, as a terminal's Ctrl-C; kill -9);
  seconds a step.

    python benchmarks/data_safety.py [--sequences 200] [--seed 0] [--steps 10] [--log FILE]   # run-dir steps
    python benchmarks/data_safety.py --real --sequences 30 --log FILE                         # real commands
tests/test_data_safety.py runs a few fixed sequences of run-dir steps in make test.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = ("r0", "r1", "r2")
KINDS = ("new", "overwrite", "overwrite", "resume", "evaluate", "export", "report", "sweep", "sweep_overwrite", "trial",
         "trial_overwrite")

# One app command in its own process: argv = kind, run dir, a pause (s) between its steps (where kills land).
COMMAND = r'''
import sys, time, json
from pathlib import Path
from ppo_torchrl import rundir
from ppo_torchrl.lifecycle import Lifecycle
from ppo_torchrl.errors import ConfigError
kind, d, pause = sys.argv[1], Path(sys.argv[2]), float(sys.argv[3])
life = Lifecycle()  # the command's claims, as __main__.cli holds them
print("ready", flush=True)  # imports done: the harness's signal lands in the command's steps
def step(): time.sleep(pause)
def train(d):  # what trainer.train writes in a claimed dir: start-up files, checkpoints, the summary
    rundir.atomic_write_bytes(d / "config.yaml", lambda f: f.write(b"seed: 1\n"))
    life.commit(d)
    for frames in (256, 512):
        step()
        rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(b"ckpt%d" % frames))
        rundir.atomic_write_json(d / "summary.json", {"status": "running", "frames": frames})
        rundir.record(d)
    rundir.atomic_write_json(d / "summary.json", {"status": "finished", "frames": 512})
    rundir.record(d)
try:
    if kind in ("new", "overwrite"):
        life.claim(d, overwrite=kind == "overwrite")
        step()
        for name in ("config", "hydra", "overrides"):
            rundir.atomic_write_bytes(d / ".hydra" / f"{name}.yaml", lambda f: f.write(b"{}\n"))
        step()
        train(d)
    elif kind == "resume":
        if not (d / "checkpoints" / "last.pt").is_file():
            raise ConfigError(f"resume={d}: not a run dir with a checkpoint")
        life.claim(d, resume=True)
        step()
        rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(b"ckpt768"))
        rundir.record(d)
    elif kind in ("sweep", "sweep_overwrite"):  # __main__.prepare claims the sweep dir, each job its own
        life.claim(d, overwrite=kind == "sweep_overwrite", what="sweep")
        step()
        for job in ("0", "1"):
            j = d / job
            life.claim(j, what="job")
            rundir.atomic_write_bytes(j / ".hydra" / "config.yaml", lambda f: f.write(b"{}\n"))
            step()
            train(j)
            life.rollback(j)
        rundir.atomic_write_bytes(d / "multirun.yaml", lambda f: f.write(b"{}\n"))
    elif kind in ("trial", "trial_overwrite"):  # a trial_seeds run: the parent of one run dir per seed
        life.claim(d, overwrite=kind == "trial_overwrite")
        rundir.atomic_write_bytes(d / ".hydra" / "config.yaml", lambda f: f.write(b"{}\n"))
        life.commit(d)
        for seed in (1, 2):
            s = d / f"seed{seed}"
            life.claim(s)
            step()
            train(s)
            life.rollback(s)
            rundir.atomic_write_json(d / "trial.json", {"seeds": [1, 2][:seed]})
            rundir.record(d)
    elif kind in ("evaluate", "export", "report"):
        if not d.is_dir():
            raise ConfigError(f"run={d}: no such run dir")
        out = {"evaluate": d / "eval" / "eval.json", "export": d / "policy.pt", "report": d / "report.png"}[kind]
        rundir.check_replaceable(d, [out])
        step()
        rundir.atomic_write_bytes(out, lambda f: f.write(b"output"), owner=d)  # the entry points' way
        rundir.record(d, [out])
except ConfigError as exc:
    life.finish()
    print(f"error: {exc}", file=sys.stderr)
    sys.exit(2)
except KeyboardInterrupt:
    life.finish()
    sys.exit(130)
life.finish()
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
        run = targets(self.root, self.rng.choice(RUNS), "evaluate", self.rng)
        kind = self.rng.choice(["file", "eval_file", "output_file", "symlink", "manifest", "replaced_file"])
        if not run.is_dir():
            return "nothing (no dir)"
        if kind == "file":
            self.add_user_file(run / "notes" / f"n{self.rng.randrange(1000)}.txt")
        elif kind == "eval_file":
            self.add_user_file(run / "eval" / "paper_numbers.csv")
        elif kind == "output_file":  # a file where the app's commands write theirs
            self.add_user_file(run / self.rng.choice(["policy.pt", "report.png", "eval/eval.json"]))
        elif kind == "replaced_file":
            self.add_user_file(run / ".replaced" / "config.yaml")
        elif kind == "symlink" and not (run / ".replaced").exists():
            (run / ".replaced").symlink_to(self.user)
        elif kind == "manifest" and (run / ".ppo_torchrl.json").is_file():
            data = json.loads((run / ".ppo_torchrl.json").read_text())
            data["files"] = list(data.get("files", [])) + ["../user/keep.txt", str(self.user / "keep.txt"), 7]
            (run / ".ppo_torchrl.json").write_text(json.dumps(data))
        return f"{kind} in {run.relative_to(self.root)}"

    def lost(self) -> list:
        """The user's files not found whole at their path nor where an overwrite moved their dir."""
        missing = []
        for rel, want in self.files.items():
            top, _, rest = rel.partition("/")
            places = [self.root / rel] + ([p / rest for p in self.root.glob(f"{top}.replaced-*")] if rest else [])
            if not any(p.is_file() and not p.is_symlink() and digest(p) == want for p in places):
                missing.append(rel)
        return missing


# The real mode: the app's own commands on a tiny env (a few seconds each), argv by kind.
TINY = ["env=InvertedPendulum-v4", "logger=none", "collector.total_frames=2048", "eval.every_frames=1024",
        "eval.episodes=2", "checkpoint.every_frames=1024"]
REAL = {
    "new": lambda d: ["-m", "ppo_torchrl", *TINY, f"hydra.run.dir={d}"],
    "overwrite": lambda d: ["-m", "ppo_torchrl", *TINY, f"hydra.run.dir={d}", "overwrite=true"],
    "resume": lambda d: ["-m", "ppo_torchrl", f"resume={d}", "collector.total_frames=4096"],
    "evaluate": lambda d: ["-m", "ppo_torchrl.evaluate", f"run={d}", "episodes=2"],
    "export": lambda d: ["-m", "ppo_torchrl.export", f"run={d}"],
    "report": lambda d: ["-m", "ppo_torchrl.report", str(d)],
    "sweep": lambda d: ["-m", "ppo_torchrl", "-m", *TINY, "seed=1,2", f"hydra.sweep.dir={d}"],
    "sweep_overwrite": lambda d: ["-m", "ppo_torchrl", "-m", *TINY, "seed=1,2", f"hydra.sweep.dir={d}", "overwrite=true"],
    "trial": lambda d: ["-m", "ppo_torchrl", *TINY, "trial_seeds=[1,2]", f"hydra.run.dir={d}"],
    "trial_overwrite": lambda d: ["-m", "ppo_torchrl", *TINY, "trial_seeds=[1,2]", f"hydra.run.dir={d}",
                                  "overwrite=true"],
}
NESTED = ("resume", "evaluate", "export", "report")  # these also go to a sweep's job or a trial's seed run


def app(kind: str, run: Path, rng: random.Random, real: bool = False) -> tuple:
    """One app command, cut by SIGINT (to its process group, as a terminal's Ctrl-C) or kill -9 at a random
    instant, or let finish: (exit code, stderr). A command that outlives its bound is a hang: code None."""
    if real:
        cmd = [sys.executable, *REAL[kind](run)]
        cut_within = 15.0  # the real commands take 2-12 s here
    else:
        cmd = [sys.executable, "-c", COMMAND, kind, str(run), str(rng.choice([0.0, 0.01, 0.03]))]
        cut_within = 0.3
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    cut = rng.choice([None, None, signal.SIGINT, signal.SIGKILL])
    if not real:
        proc.stdout.readline()  # "ready" (or nothing: it ended): the signal lands in the command's steps
    if cut is not None:
        try:
            proc.wait(timeout=rng.uniform(0.0, cut_within))
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, cut)
    try:
        _, err = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        _, err = proc.communicate()
        return None, "hang: still running after 300 s\n" + err
    return proc.returncode, err


def explained(code, err: str) -> bool:
    """The command worked, was cut by its signal (a SIGINT that lands in its error path ends it by the
    signal), or said why in an `error:` line with no traceback."""
    lines = [line for line in err.splitlines() if line.strip()]
    if code in (0, 130, -signal.SIGINT, -signal.SIGKILL):
        return "Traceback" not in err or code == -signal.SIGINT
    return code == 2 and "Traceback" not in err and sum(line.startswith("error:") for line in lines) == 1


def targets(root: Path, name: str, kind: str, rng: random.Random) -> Path:
    """Where a command (or a user's edit) goes: the top dir, or for one that reads a run, at random a run dir
    inside it (a sweep's job, a trial's seed)."""
    top = root / name
    inner = sorted(p.parent for p in top.glob("*/.ppo_torchrl.json")) if top.is_dir() else []
    return rng.choice([top, *inner]) if kind in NESTED and inner else top


_START: dict = {}


def start_tree(real: bool) -> Path:
    """Made once per process: the tree each sequence starts from (r0 a finished run, r1 a finished sweep of two
    jobs, r2 a finished trial of two seeds), by the same commands, let finish."""
    if real not in _START:
        root = Path(tempfile.mkdtemp(prefix="data_safety_start_"))
        for kind, name in (("new", "r0"), ("sweep", "r1"), ("trial", "r2")):
            cmd = [sys.executable, *REAL[kind](root / name)] if real else [sys.executable, "-c", COMMAND, kind,
                                                                          str(root / name), "0"]
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
            if proc.returncode != 0:
                raise RuntimeError(f"{kind} {name} exited {proc.returncode}: {proc.stderr[-600:]}")
        _START[real] = root
    return _START[real]


def sequence(seed: int, steps: int = 10, real: bool = False, log=None) -> list:
    """One random sequence; returns its failures (empty: every user byte kept, every dir usable or explained).
    log: a list that gets one line per step (what ran, how it ended, its error line)."""
    rng = random.Random(seed)
    failures = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in RUNS:  # r0 a finished run, r1 a sweep of two jobs, r2 a trial of two seeds (copied)
            shutil.copytree(start_tree(real) / name, Path(tmp) / name, symlinks=True)
        tree = Tree(Path(tmp), rng)
        for i in range(steps):
            if rng.random() < 0.35:
                what = "user: " + tree.user_step()
            else:
                kind = rng.choice(KINDS)
                run = targets(tree.root, rng.choice(RUNS), kind, rng)
                code, err = app(kind, run, rng, real)
                said = next((line for line in err.splitlines() if line.startswith("error:")), "")
                what = f"{kind} {run.relative_to(tree.root)} -> {code} {said}"
                if not explained(code, err):
                    failures.append(f"seed {seed} step {i} {what}: {err.strip()[-600:]}")
            if log is not None:
                log.append(f"seed {seed} step {i}: {what}")
            lost = tree.lost()
            if lost:
                failures.append(f"seed {seed} step {i} ({what}): user files lost: {lost}")
                break
        for run in RUNS:  # every dir left: a new command there works or is explained
            if (tree.root / run).exists():
                code, err = _plain(tree.root / run, real)
                if not explained(code, err):
                    failures.append(f"seed {seed} end: {run} not usable: {err.strip()[-600:]}")
                if log is not None:
                    log.append(f"seed {seed} end: overwrite {run} -> {code} "
                               + next((line for line in err.splitlines() if line.startswith("error:")), ""))
        lost = tree.lost()
        if lost:
            failures.append(f"seed {seed} end: user files lost: {lost}")
    return failures


def _plain(run: Path, real: bool = False) -> tuple:
    """overwrite=true in `run`, let finish."""
    cmd = [sys.executable, *REAL["overwrite"](run)] if real else [sys.executable, "-c", COMMAND, "overwrite", str(run), "0"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    return proc.returncode, proc.stderr


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--real", action="store_true", help="the app's real commands (train, sweep, trial, resume, "
                        "overwrite, evaluate, report, export) on InvertedPendulum: seconds a step, not milliseconds")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--log", help="write every step (command, exit code, error line) to this file")
    args = parser.parse_args(argv)
    start, failures, log = time.time(), [], []
    for k in range(args.sequences):
        failures += sequence(args.seed * 100_000 + k, args.steps, args.real, log)
        if args.log:
            Path(args.log).write_text("\n".join(log) + "\n")
    ran = [line for line in log if " -> " in line]
    print(f"{args.sequences} sequences of {args.steps} steps ({'real commands' if args.real else 'run-dir steps'}; "
          f"seeds {args.seed * 100_000}..{args.seed * 100_000 + args.sequences - 1}) in {time.time() - start:.0f} s: "
          f"{len(ran)} commands, {sum(' -> 2 ' in line for line in ran)} refused with an error line; "
          f"{len(failures)} failures (user files lost or a dir left unusable or unexplained)")
    for failure in failures:
        print(failure)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
