"""The data-safety property (issue 47, item 5; issue 60, item 4): random sequences of the app's commands (train,
sweep, trial, resume, overwrite, evaluate, report, export), each cut by a random SIGINT or kill -9 or let finish, on
a tree that holds the user's files (beside the app's, and where the app writes its outputs), symlinks and edited
manifests. Each sequence starts from r0 a finished run, r1 a finished sweep of two jobs and r2 a finished trial
of two seeds; commands that read a run also go to a sweep's job or a trial's seed. After every step each user
byte is still there (its hash, at its path or in the sibling an overwrite moved its dir to), and at the end
every dir is usable or explained (`overwrite=true` there works or is one `error:` line, never a traceback).

Five more cases (issue 60, item 4), drawn as commands are:
- evaluate_out: evaluate with out= its run's eval dir spelled otherwise (relative, `<run>/../<run>/eval`, through a
  symlink to the run) or another run's dir (`<other>/eval`, `<other>`), where a user's eval.json may be.
- race: a reader (evaluate, export, report) and an overwrite of its run's top dir started together, each cut at
  random; an eval.json of the app's that the race wrote must be of the run's checkpoint now (run-dir steps: the
  sha256 of the last.pt it read; --real: a second evaluate gives its returns and checkpoint frames).
- claim_cut: an overwrite (or a new run, sweep, trial) stopped by kill -9 or Ctrl-C at step k of a claim (before or
  after each rename, manifest temp file, fsync, replace: the command prints `claim-step k` and waits); then resume,
  or the overwrite again, takes the dir or its refusal names the `<dir>.replaced-*` sibling the cut left.
- full_disk: a command under a small file-size limit (RLIMIT_FSIZE, SIGXFSZ ignored: a write fails midway, EFBIG),
  then overwrite=true of its top dir; each works or is one line.
- optuna (--real only): `-m hparams_search=optuna_seeds` (2 trials, seeds 6,7, 1,024 frames: ~15 s) cut at random;
  then the same command, resume=<sweep>/0 and the command with overwrite=true, each let finish.
In these, a refusal that calls a file not the app's must name a file of the user's.

Round 6 (issue 76, item 3): `records` (run-dir steps: on the run's config.yaml), and with --real the Python API
(api_train, api_overwrite, api_resume, api_load, api_evaluate: a script's train / load().predict / evaluate_run) and
`crafted` (a real run's copy whose checkpoints carry a payload aimed at a user's file, read by a random entry point):
data_safety_round6.py says how.

Two modes, one property:
- run-dir steps (default): each command is a fresh process that makes the entry points' `ppo_torchrl.run.rundir`
  calls in their order (claims, Hydra's start-up files, commits, atomic checkpoints and summaries, listings,
  readers' shared locks, outputs written through `owner=`, the one error path of errors.py), with pauses where
  the kills land; milliseconds a step.
- `--real`: the app's own commands (`python -m ppo_torchrl ...`, `-m` sweeps, `trial_seeds`, `resume=`,
  `overwrite=true`, `ppo_torchrl.evaluate`, `.export`, `.report`) on InvertedPendulum-v4 with 2,048 frames,
  cut at a random instant in their first 15 s (SIGINT to the process group, as a terminal's Ctrl-C; kill -9);
  seconds a step.

    python benchmarks/data_safety.py [--sequences 200] [--seed 0] [--steps 10] [--log FILE]   # run-dir steps
    python benchmarks/data_safety.py --real --sequences 30 --log FILE                         # real commands
    python benchmarks/data_safety.py --kinds race,claim_cut ...          # draw only these kinds (user edits stay)
tests/test_data_safety.py runs a few fixed sequences of run-dir steps in make test.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from ppo_torchrl.run import rundir  # noqa: E402  (the manifest's reading: which eval.json is the app's)
sys.path.insert(0, str(ROOT / "benchmarks"))
from data_safety_round6 import API_KINDS, API_NESTED, api_argv, crafted_case  # noqa: E402

RUNS = ("r0", "r1", "r2")
KINDS = ("new", "overwrite", "overwrite", "resume", "evaluate", "export", "report", "sweep", "sweep_overwrite", "trial",
         "trial_overwrite", "records")
CASES = ("evaluate_out", "evaluate_out", "race", "race", "claim_cut", "claim_cut", "full_disk")  # issue 60, item 4
REAL_CASES = ("optuna", "crafted", "crafted")  # crafted: issue 76, item 3
REAL_KINDS = API_KINDS  # the Python API's entry points (issue 76, item 3)
OVERWRITES = ("overwrite", "sweep_overwrite", "trial_overwrite")
ENV = {**os.environ, "PYTHONWARNINGS": "ignore"}
# How a command is started: subprocess.Popen here; the tests set their launcher (tests/conftest.py: launch), a real
# process forked from an interpreter that has imported the app's libraries once, taking the same arguments.
LAUNCH = None


def popen(argv, fsize=None, **kwargs):
    """A process for `argv` (subprocess.Popen's keywords; fsize: RLIMIT_FSIZE in bytes, a write past it failing with
    EFBIG, as on a full disk), with SIGINT as a terminal gives it: a harness started in the background (`cmd &`) has
    SIGINT ignored, which its children would inherit (a Ctrl-C then does nothing: a wait on the next claim step, a
    false hang)."""
    if LAUNCH is not None:
        return LAUNCH(argv, fsize=fsize, **kwargs)

    def limit():
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)

    return subprocess.Popen(argv, preexec_fn=limit, **kwargs)


def finished(argv, timeout=300) -> tuple:
    """Run `argv` to its end: (exit code, stderr); subprocess.TimeoutExpired past `timeout` (the process killed)."""
    proc = popen(argv, cwd=ROOT, env=ENV, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                 text=True)
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    return proc.returncode, err

# One app command in its own process: argv = kind, run dir, a pause (s) between its steps (where kills land)[, out].
COMMAND = r'''
import sys, time, json, hashlib
from pathlib import Path
from ppo_torchrl.run import rundir
from ppo_torchrl.run.lifecycle import Lifecycle
from ppo_torchrl.errors import ConfigError, guarded, report_and_exit
from ppo_torchrl.run.locks import read
from ppo_torchrl.run.ownership import holder
from ppo_torchrl.run.signals import ignore_from_now
kind, d, pause = sys.argv[1], Path(sys.argv[2]), float(sys.argv[3])
out_dir = Path(sys.argv[4]) if len(sys.argv) > 4 else d / "eval"  # evaluate's out=
life = Lifecycle()  # the command's claims, as __main__.cli holds them
print("ready", flush=True)  # imports done: the harness's signal lands in the command's steps
def step(): time.sleep(pause)
def train(d):  # what trainer.train writes in a claimed dir: start-up files, checkpoints, the summary
    rundir.atomic_write_bytes(d / "config.yaml", lambda f: f.write(b"seed: 1\n"))
    life.commit(d)
    for frames in (256, 512):
        step()
        ckpt = b"ckpt%d %d" % (frames, time.time_ns())  # each checkpoint's bytes its own (the race's check)
        rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(ckpt))
        if frames == 256:  # trainer.write_summary: its first write listed first (write-ahead)
            rundir.intend(d, [d / "summary.json"])
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
    elif kind == "resume":  # Lifecycle.resume's refusal names the sibling an overwrite moved the run to
        if not (d / "checkpoints" / "last.pt").is_file():
            aside = rundir.moved_aside(d)
            raise ConfigError(f"resume={d}: not a run dir with a checkpoint" + (
                f"; overwrite=true moved the run that was there to {aside}: resume={aside}" if aside else ""))
        life.claim(d, resume=True)
        step()
        rundir.atomic_write_bytes(d / "checkpoints" / "last.pt", lambda f: f.write(b"ckpt768 %d" % time.time_ns()))
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
            if seed == 1:  # sweeps.run_trial: the first write listed first (write-ahead)
                rundir.intend(d, [d / "trial.json"])
            rundir.atomic_write_json(d / "trial.json", {"seeds": [1, 2][:seed]})
            rundir.record(d)
    elif kind == "records":  # records.main itself: the run's lock, its record listed (the config.yaml train() wrote)
        from ppo_torchrl import records
        records.main([str(d / "config.yaml")])
    elif kind in ("evaluate", "export", "report"):
        if not d.is_dir():
            raise ConfigError(f"run={d}: no such run dir")
        read(d)  # the readers' shared lock (run/locks.py): no overwrite starts there while it reads
        if not (d / "checkpoints" / "last.pt").is_file():  # as checkpoint.resolve_checkpoint (report: metrics.csv)
            raise ConfigError(f"run={d} is not a ppo_torchrl run dir (no checkpoint)")
        out = {"evaluate": out_dir / "eval.json", "export": d / "policy.pt", "report": d / "report.png"}[kind]
        rundir.check_replaceable(d, [out])
        read(holder(out))  # out= in another run dir: that one is read (and written) too
        made = hashlib.sha256((d / "checkpoints" / "last.pt").read_bytes()).hexdigest()  # recorded: the race's check
        step()
        rundir.atomic_write_bytes(out, lambda f: f.write(json.dumps({"checkpoint": made}).encode()), owner=d)
        rundir.record(d, [out])
except BaseException as exc:  # the entry points' one error path (errors.py): one line and its exit code
    try:
        guarded(life.finish)
        report_and_exit(exc)
    finally:
        ignore_from_now()  # as the entry points end: a signal during Python's shutdown does nothing
guarded(life.finish)
ignore_from_now()
'''

# claim_cut: prepended to a command, it makes each step of a claim (Lifecycle.claim: a rename, the manifest's temp
# file, its fsync, its replace) print `claim-step k` before and after and wait for a line on stdin (the harness
# answers, or kills it there).
HOOK = r'''
import os, sys, tempfile
from ppo_torchrl.run.lifecycle import Lifecycle
_at = [0, 0]  # claims under way, steps so far
def _hooked(call, claim=False):  # claim: counts the claims under way; else a step before and after, in one
    def step():
        if _at[0] and not claim:
            print(f"claim-step {_at[1]}", flush=True)
            _at[1] += 1
            sys.stdin.readline()
    def hooked(*args, **kwargs):
        step()
        _at[0] += claim
        try:
            return call(*args, **kwargs)
        finally:
            _at[0] -= claim
            step()
    return hooked
for _module, _name in ((os, "rename"), (os, "replace"), (os, "fsync"), (tempfile, "mkstemp")):
    setattr(_module, _name, _hooked(getattr(_module, _name)))
Lifecycle.claim = _hooked(Lifecycle.claim, claim=True)
'''
RUNPY = "import runpy\nsys.argv.pop(0)\nrunpy.run_module(sys.argv[0], run_name='__main__', alter_sys=True)\n"


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
    "records": lambda d: ["-m", "ppo_torchrl.records", str(d / "metrics.csv"), str(d / "checkpoints" / "last.pt")],
    **{kind: (lambda d, kind=kind: api_argv(kind, d, TINY)) for kind in API_KINDS},
    "init_from": lambda d: ["-m", "ppo_torchrl", *TINY, f"init_from={d / 'checkpoints' / 'last.pt'}",
                            f"hydra.run.dir={d.parent / ('init_' + d.name)}"],
    "optuna": lambda d: ["-m", "ppo_torchrl", "-m", "hparams_search=optuna_seeds", *TINY, "collector.total_frames=1024",
                         "collector.frames_per_batch=1024", "trial_seeds=[6,7]", "hydra.sweeper.n_trials=2",
                         f"hydra.sweeper.storage=sqlite:///{d.parent / 'optuna.db'}", f"hydra.sweep.dir={d}"],
}
NESTED = ("resume", "evaluate", "export", "report", "records")  # these also go to a sweep's job or a trial's seed run


def command(kind: str, run: Path, real: bool, pause: str = "0", extra=(), hooked: bool = False) -> list:
    """The argv of one app command; hooked: its claims stop at each step (HOOK)."""
    if real:
        argv = [*REAL[kind](run), *extra]
        return [sys.executable, "-c", HOOK + RUNPY, *argv[1:]] if hooked else [sys.executable, *argv]
    return [sys.executable, "-c", (HOOK if hooked else "") + COMMAND, kind, str(run), pause, *extra]


def spawn(kind: str, run: Path, rng: random.Random, real: bool, extra=(), fsize=None, hooked=False):
    """Start one app command in its own process group (its claims stopped at each step if hooked), under a
    file-size limit of `fsize` bytes if given (a write past it fails, EFBIG, as on a full disk)."""
    proc = popen(command(kind, run, real, str(rng.choice([0.0, 0.01, 0.03])), extra, hooked), fsize=fsize, cwd=ROOT,
                 env=ENV, stdin=subprocess.PIPE if hooked else subprocess.DEVNULL, stdout=subprocess.PIPE,
                 stderr=subprocess.PIPE, text=True, start_new_session=True)
    if not real and not hooked:
        proc.stdout.readline()  # "ready" (or nothing: it ended): the signal lands in the command's steps
    return proc


def cut(procs: list, rng: random.Random, within: float) -> None:
    """Cut each process by SIGINT (to its process group, as a terminal's Ctrl-C) or kill -9 at a random instant
    in its first `within` s, or let it finish."""
    start = time.time()
    plan = [(rng.uniform(0.0, within), rng.choice([None, None, signal.SIGINT, signal.SIGKILL]), p) for p in procs]
    for at, signum, proc in sorted(plan, key=lambda planned: planned[0]):
        if signum is not None:
            try:
                proc.wait(timeout=max(0.0, start + at - time.time()))
            except subprocess.TimeoutExpired:
                signal_group(proc, signum)


def signal_group(proc, signum) -> None:
    """`signum` to the command's process group; none left (it ended between the wait and now, and was reaped:
    the tests' launcher reaps at once) is the command let finish."""
    try:
        os.killpg(proc.pid, signum)
    except ProcessLookupError:
        pass


def ended(proc) -> tuple:
    """(exit code, stderr); a command that outlives its bound is a hang: code None."""
    try:
        _, err = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        signal_group(proc, signal.SIGKILL)
        return None, "hang: still running after 300 s\n" + proc.communicate()[1]
    return proc.returncode, err


def app(kind: str, run: Path, rng: random.Random, real: bool = False, extra=(), fsize=None, cuts=True,
        within=15.0) -> tuple:
    """One app command, cut at random (cuts=False: let finish): (exit code, stderr)."""
    proc = spawn(kind, run, rng, real, extra, fsize)
    if cuts:
        cut([proc], rng, within if real else 0.3)  # the real commands take 2-12 s here
    return ended(proc)


def explained(code, err: str) -> bool:
    """The command worked, was cut by its signal (a SIGINT that lands in its error path ends it by the
    signal), or said why in an `error:` line with no traceback (exit 2: the input; 1: the machine, e.g. a full
    disk, never an internal error)."""
    lines = [line for line in err.splitlines() if line.strip()]
    if code in (0, 130, -signal.SIGINT, -signal.SIGKILL):
        return "Traceback" not in err or code == -signal.SIGINT
    return (code == 2 or code == 1 and "error: internal error" not in err) and "Traceback" not in err \
        and sum(line.startswith("error:") for line in lines) == 1


def said(err: str) -> str:
    return next((line for line in err.splitlines() if line.startswith("error:")), "")


FOREIGN = re.compile(r"^error: (\S+) is not empty and is not a ppo_torchrl \w+ dir \(it holds (.+?)(?: and \d+ more)?, "
                     r"which this app did not write\)")
NOT_WRITTEN = re.compile(r"^error: (\S+)(?: \(that is (\S+)\))? is not a file this app wrote")


def called_foreign(err: str, tree) -> list:
    """The files a refusal calls not the app's that are not the user's (the app's own, left unlisted)."""
    line, names = said(err), []
    if FOREIGN.match(line):
        top, shown = FOREIGN.match(line).groups()
        names = [Path(top) / name for name in shown.split(", ") if name != "folders"]
    elif NOT_WRITTEN.match(line):
        spelled, real = NOT_WRITTEN.match(line).groups()
        names = [Path(real or spelled)]
    rels = [os.path.relpath(os.path.realpath(ROOT / path), tree.root.resolve()) for path in names]
    return [rel for rel in rels if re.sub(r"^([^/]+)\.replaced-[^/]+/", r"\1/", rel) not in tree.files]  # a user's?


def targets(root: Path, name: str, kind: str, rng: random.Random) -> Path:
    """Where a command (or a user's edit) goes: the top dir, or for one that reads a run, at random a run dir
    inside it (a sweep's job, a trial's seed)."""
    top = root / name
    inner = sorted(p.parent for p in top.glob("*/.ppo_torchrl.json")) if top.is_dir() else []
    return rng.choice([top, *inner]) if kind in NESTED + API_NESTED and inner else top


def siblings(top: Path) -> set:
    return set(top.parent.glob(f"{top.name}.replaced-*"))


def checked(what: str, code, err: str, tree=None) -> list:
    """The failures of one command's ending: unexplained, or (tree given) the app's own files called not its."""
    bad = [] if explained(code, err) else [f"{what} -> {code}: {err.strip()[-600:]}"]
    wrong = called_foreign(err, tree) if tree is not None and code in (1, 2) else []
    return bad + ([f"{what}: its refusal calls the app's own files not the app's: {wrong}"] if wrong else [])


def evaluate_out(tree, rng, real) -> tuple:
    """evaluate writing to its run's eval dir spelled otherwise, or to another run's dir."""
    run = targets(tree.root, rng.choice(RUNS), "evaluate", rng)
    other = targets(tree.root, rng.choice(RUNS), "evaluate", rng)
    way = rng.choice(["relative", "dotdot", "symlink", "other", "other_top"])
    if way == "symlink":
        link = tree.root / "links" / f"l{rng.randrange(10**6)}"
        link.parent.mkdir(exist_ok=True)
        link.symlink_to(run)
    out = {"relative": lambda: os.path.relpath(run / "eval", ROOT), "dotdot": lambda: f"{run}/../{run.name}/eval",
           "symlink": lambda: f"{link}/eval", "other": lambda: str(other / "eval"),
           "other_top": lambda: str(other)}[way]()
    written = Path(os.path.realpath(ROOT / out)) / "eval.json"
    rel, mine = os.path.relpath(written, tree.root.resolve()), rundir.holder(written) is None
    if mine:  # out= outside any run dir: a folder of the user's, its eval.json theirs to have replaced
        tree.files.pop(rel, None)
    code, err = app("evaluate", run, rng, real, extra=[f"out={out}" if real else out])
    if mine and code == 0 and written.is_file():  # and the new one theirs
        tree.files[rel] = digest(written)
    what = f"evaluate {run.relative_to(tree.root)} out={out} ({way}) -> {code} {said(err)}"
    return what, checked(what, code, err, tree)


def race(tree, rng, real) -> tuple:
    """A reader and an overwrite of its run's top dir started together, each cut at random (or let finish)."""
    top = tree.root / rng.choice(RUNS)
    run = targets(tree.root, top.name, "evaluate", rng)
    reader, writer = rng.choice(["evaluate", "evaluate", "export", "report"]), rng.choice(OVERWRITES)
    ev = run / "eval" / "eval.json"
    before = digest(ev) if ev.is_file() else None
    procs = [spawn(reader, run, rng, real), spawn(writer, top, rng, real)]
    cut(procs, rng, 15.0 if real else 0.3)
    (code, err), (code2, err2) = [ended(proc) for proc in procs]
    what = (f"race {reader} {run.relative_to(tree.root)} -> {code} {said(err)} | {writer} {top.name} -> {code2} "
            f"{said(err2)}")
    failures = checked(f"race {reader}", code, err, tree) + checked(f"race {writer}", code2, err2, tree)
    now = digest(ev) if ev.is_file() and not ev.is_symlink() else None
    if now is not None and now != before and now in rundir.digests(run).get("eval/eval.json", []):
        stale = stale_eval(tree, run, ev, real)  # an eval.json the race wrote, the app's: of the run's checkpoint?
        what += f" (its eval.json: {stale or 'of its checkpoint now'})"
        if stale:
            failures.append(f"{what}: {run.relative_to(tree.root)}/eval/eval.json is not its checkpoint's")
    return what, failures


def stale_eval(tree, run: Path, ev: Path, real: bool):
    """Why eval.json was not made from the run's checkpoint now, or None when it was (or cannot be told)."""
    made = json.loads(ev.read_text())  # the app's (its sha256 in the manifest): JSON
    if not real:  # the run-dir steps' eval.json holds the sha256 of the last.pt it read
        now = digest(run / "checkpoints" / "last.pt") if (run / "checkpoints" / "last.pt").is_file() else None
        return None if made.get("checkpoint") in (None, now) else f"made from {made['checkpoint']}, last.pt is {now}"
    code, err = finished([sys.executable, "-m", "ppo_torchrl.evaluate", f"run={run}", "episodes=2",
                          f"out={tree.root / 'check'}"])
    if code != 0:
        return f"it cannot be evaluated again: {said(err) or err[-300:]}"
    fresh = json.loads((tree.root / "check" / "eval.json").read_text())
    keys = ("checkpoint", "checkpoint_frames", "returns")
    return None if all(made.get(k) == fresh.get(k) for k in keys) else \
        f"{[made.get(k) for k in keys]} there, {[fresh.get(k) for k in keys]} from the checkpoint now"


def answer(proc) -> None:
    """Let a command paused at a claim step (HOOK) go on."""
    with contextlib.suppress(OSError, ValueError):  # it ended meanwhile (a closed pipe)
        proc.stdin.write("go\n")
        proc.stdin.flush()


def claim_cut(tree, rng, real) -> tuple:
    """A claim stopped at its step k by kill -9 or Ctrl-C; then resume, or the same overwrite, let finish."""
    top = tree.root / rng.choice(RUNS)
    kind = rng.choice(["overwrite", *OVERWRITES] if top.exists() else ["new", "sweep", "trial"])
    k, signum = rng.randrange(8 if kind in ("overwrite", "new") else 14), rng.choice([signal.SIGINT, signal.SIGKILL])
    before, proc, n = siblings(top), spawn(kind, top, rng, real, hooked=True), 0
    hang = threading.Timer(300, signal_group, (proc, signal.SIGKILL))
    hang.start()
    for line in proc.stdout:  # (stderr stays in its pipe: a few kB)
        if line.startswith("claim-step"):
            if n == k:
                os.killpg(proc.pid, signum)
                # A Ctrl-C the app defers (the loop's StopRequest: stop after this iteration) leaves it waiting on
                # this step's line, where a real rename would have gone on: answer it after a while, so the command
                # ends by itself (or hangs by its own fault, which the 300 s bound still catches).
                threading.Timer(5, answer, (proc,)).start()
            else:
                answer(proc)
            n += 1
    code, err = ended(proc)
    hung = hang.finished.is_set()  # before cancel(): set only if the timer fired
    hang.cancel()
    if hung:
        code, err = None, "hang: still running 300 s after its claim began\n" + err
    new = siblings(top) - before if k < n else set()  # a command that ended before step k was not cut
    then = rng.choice(["resume", kind if kind in OVERWRITES else "overwrite"])
    code2, err2 = app(then, top, rng, real, cuts=False)
    named = [s.name for s in new if str(s) in err2]
    what = (f"claim_cut {kind} {top.name} at claim-step {k} of {n} by {signal.Signals(signum).name} -> {code} "
            f"{said(err)}; then {then} -> {code2} {said(err2)} (siblings new: {sorted(s.name for s in new)}, "
            f"named: {named})")
    failures = checked(f"claim_cut {kind}", code, err) + checked(f"then {then}", code2, err2, tree)
    # a sibling the cut command did not name: a refusal names it, and so does the start that takes the dir when the
    # cut landed in the top dir's own claim (k < 8)
    if new and not any(str(s) in err for s in new) and not named and (code2 != 0 or k < 8):
        failures.append(f"{what}: the sibling the cut left is not named")
    return what, failures


def full_disk(tree, rng, real) -> tuple:
    """A command under a small file-size limit; then overwrite=true of its top dir, let finish."""
    kind = rng.choice(OVERWRITES + NESTED + (API_NESTED if real else ()))
    run = targets(tree.root, rng.choice(RUNS), kind, rng)
    fsize = rng.choice([200, 2_000, 20_000, 100_000] if real else [0, 100, 300, 1_000])  # real: 0 fails torch's import
    code, err = app(kind, run, rng, real, fsize=fsize, cuts=False)
    top = tree.root / run.relative_to(tree.root).parts[0]
    code2, err2 = _plain(top, real)
    what = (f"full_disk {kind} {run.relative_to(tree.root)} at {fsize} bytes -> {code} {said(err)}; then overwrite "
            f"{top.name} -> {code2} {said(err2)}")
    return what, checked(f"full_disk {kind}", code, err, tree) + checked("then overwrite", code2, err2, tree)


def optuna(tree, rng, real) -> tuple:
    """An optuna_seeds sweep cut at random; then the same command, resume=<sweep>/0, and it with overwrite=true."""
    top = tree.root / rng.choice(RUNS)
    ends = [("optuna overwrite=true (cut)", *app("optuna", top, rng, real, extra=["overwrite=true"], within=20.0))]
    ends.append(("optuna", *app("optuna", top, rng, real, cuts=False)))
    ends.append((f"resume {top.name}/0", *app("resume", top / "0", rng, real, cuts=False)))
    ends.append(("optuna overwrite=true", *app("optuna", top, rng, real, extra=["overwrite=true"], cuts=False)))
    what = f"optuna {top.name}: " + "; ".join(f"{name} -> {code} {said(err)}" for name, code, err in ends)
    return what, [f for name, code, err in ends for f in checked(name, code, err, tree)]


def crafted(tree, rng, real) -> tuple:
    """data_safety_round6.crafted, with this module's helpers (a crafted checkpoint read by a random entry point)."""
    return crafted_case(tree, rng, real, sys.modules[__name__])


_START: dict = {}


def start_tree(real: bool) -> Path:
    """Made once per process: the tree each sequence starts from (r0 a finished run, r1 a finished sweep of two
    jobs, r2 a finished trial of two seeds), by the same commands, let finish."""
    if real not in _START:
        root = Path(tempfile.mkdtemp(prefix="data_safety_start_"))
        for kind, name in (("new", "r0"), ("sweep", "r1"), ("trial", "r2")):
            code, err = finished(command(kind, root / name, real))
            if code != 0:
                raise RuntimeError(f"{kind} {name} exited {code}: {err[-600:]}")
        _START[real] = root
    return _START[real]


def sequence(seed: int, steps: int = 10, real: bool = False, log=None, kinds=None, order=None) -> list:
    """One random sequence; returns its failures (empty: every user byte kept, every dir usable or explained).
    log: a list that gets one line per step (what ran, how it ended, its error line). kinds: draw only these.
    order: these kinds, one a step in this order (a user's edit before each), in place of the draws."""
    rng = random.Random(seed)
    steps = 2 * len(order) if order else steps
    failures = []
    drawn = [k for k in KINDS + CASES + (REAL_CASES + REAL_KINDS if real else ()) if kinds is None or k in kinds]
    with tempfile.TemporaryDirectory() as tmp:
        for name in RUNS:  # r0 a finished run, r1 a sweep of two jobs, r2 a trial of two seeds (copied)
            shutil.copytree(start_tree(real) / name, Path(tmp) / name, symlinks=True)
        tree = Tree(Path(tmp), rng)
        for i in range(steps):
            if (order and i % 2 == 0) or (not order and (rng.random() < 0.35 or not drawn)):
                what = "user: " + tree.user_step()
            else:
                kind = order[i // 2] if order else rng.choice(drawn)
                if kind in CASES + REAL_CASES:
                    what, failed = globals()[kind](tree, rng, real)
                    failures += [f"seed {seed} step {i} {failure}" for failure in failed]
                else:
                    run = targets(tree.root, rng.choice(RUNS), kind, rng)
                    code, err = app(kind, run, rng, real)
                    what = f"{kind} {run.relative_to(tree.root)} -> {code} {said(err)}"
                    failures += [f"seed {seed} step {i} {failure}" for failure in checked(what, code, err, tree)]
            if log is not None:
                log.append(f"seed {seed} step {i}: {what}")
            lost = tree.lost()
            if lost:
                failures.append(f"seed {seed} step {i} ({what}): user files lost: {lost}")
                break
        for run in RUNS:  # every dir left: a new command there works or is explained
            if (tree.root / run).exists():
                code, err = _plain(tree.root / run, real)  # usable, or a refusal naming a user's file (never the app's)
                failures += [f"seed {seed} end: {run} not usable: {failure}"
                             for failure in checked(f"overwrite {run}", code, err, tree)]
                if log is not None:
                    log.append(f"seed {seed} end: overwrite {run} -> {code} {said(err)}")
        lost = tree.lost()
        if lost:
            failures.append(f"seed {seed} end: user files lost: {lost}")
    return failures


def _plain(run: Path, real: bool = False) -> tuple:
    """overwrite=true in `run`, let finish."""
    return finished(command("overwrite", run, real))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--real", action="store_true", help="the app's real commands (train, sweep, trial, resume, "
                        "overwrite, evaluate, report, export) on InvertedPendulum: seconds a step, not milliseconds")
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--kinds", help="draw only these kinds of command, comma-separated (e.g. race,claim_cut)")
    parser.add_argument("--log", help="write every step (command, exit code, error line) to this file")
    args = parser.parse_args(argv)
    kinds = set(args.kinds.split(",")) if args.kinds else None
    known = set(KINDS + CASES + REAL_CASES + REAL_KINDS)
    unknown = (kinds or set()) - known
    if unknown:
        parser.error(f"unknown kinds {sorted(unknown)}; known: {', '.join(sorted(known))}")
    start, failures, log = time.time(), [], []
    for k in range(args.sequences):
        failures += sequence(args.seed * 100_000 + k, args.steps, args.real, log, kinds)
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
