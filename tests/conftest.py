"""Shared fixtures: configs composed with Hydra's compose API, the way the app composes them."""

from __future__ import annotations

import atexit
import json
import os
import selectors
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

import ppo_torchrl.config  # noqa: F401  (registers the schemas)

ROOT = Path(__file__).resolve().parent.parent
CONF = str(ROOT / "conf")

# A tiny run: two batches of 256 frames, 2 epochs of 4 minibatches, no periodic eval.
TINY = [
    "collector.frames_per_batch=256",
    "collector.total_frames=512",
    "loss.epochs=2",
    "loss.minibatch_size=64",
    "eval.every_frames=0",
    "eval.final_episodes=1",
    "checkpoint.every_frames=256",
    "logger=none",
]


def compose_config(overrides=(), return_hydra_config=False):
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=CONF, version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides), return_hydra_config=return_hydra_config)


@pytest.fixture
def tiny_cfg():
    def make(*overrides):
        return compose_config(["env=InvertedPendulum-v4", *TINY, *overrides])

    return make


def app_env(**extra):
    """The environment of an app launch: the tests' own, warnings off, no debug tracebacks."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore", **extra}
    env.pop("PPO_TORCHRL_DEBUG", None)
    return env


class _Server:
    """This test worker's app launcher (tests/appserver.py), started at its first launch."""

    process = None
    path = None

    @classmethod
    def address(cls):
        if cls.process is None or cls.process.poll() is not None:
            cls.path = os.path.join(tempfile.mkdtemp(prefix="ppo_torchrl_appserver_"), "socket")
            env = app_env()
            env.pop("PYTHONWARNINGS")  # a user's start; a launch with PYTHONWARNINGS=ignore sets it in its child
            cls.process = subprocess.Popen([sys.executable, str(ROOT / "tests" / "appserver.py"), cls.path], cwd=ROOT,
                                           env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
            ready = cls.process.stdout.readline()  # bounded: the server prints "ready" or ends (EOF)
            assert ready.strip() == "ready", f"the tests' app launcher did not start (exit {cls.process.poll()})"
            atexit.register(cls.process.terminate)  # it kills the launches a failed test left, then ends
        return cls.path


class App:
    """A launch of `python -m <module> ARGS` through the launcher: a real process, used as subprocess.Popen is."""

    def __init__(self, args, module="ppo_torchrl", cwd=None, env=None, stdout=None, stderr=None, text=True,
                 start_new_session=False, stdin=None, code=None, fsize=None):
        """`code`: `python -c code ARGS` instead of `-m module`; `fsize`: RLIMIT_FSIZE in bytes (SIGXFSZ ignored, so a
        write past it fails with EFBIG as on a full disk)."""
        ends = {}
        mine = []
        for name, how in (("stdout", stdout), ("stderr", stderr)):
            if how == subprocess.PIPE:
                read, write = os.pipe()
                ends[name] = os.fdopen(read, "r" if text else "rb")
                mine.append(write)
            elif how == subprocess.DEVNULL:
                mine.append(os.open(os.devnull, os.O_WRONLY))
            elif how == subprocess.STDOUT:
                mine.append(None)
            else:
                mine.append(os.dup(1 if name == "stdout" else 2))
        if mine[1] is None:
            mine[1] = os.dup(mine[0])
        self.stdin = None
        if stdin == subprocess.PIPE:
            read, write = os.pipe()
            self.stdin = os.fdopen(write, "w" if text else "wb")
            stdin = read
        else:
            stdin = os.open(os.devnull, os.O_RDONLY)
        fds = [stdin, *mine]
        self.stdout, self.stderr = ends.get("stdout"), ends.get("stderr")
        self.args = [sys.executable, *(["-c", code] if code is not None else ["-m", module]), *map(str, args)]
        self.returncode = None
        self._conn = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            self._conn.connect(_Server.address())
            request = {"module": module, "code": code, "args": [str(a) for a in args], "cwd": str(cwd or ROOT),
                       "env": env if env is not None else app_env(), "new_session": start_new_session, "fsize": fsize}
            socket.send_fds(self._conn, [json.dumps(request).encode() + b"\n"], fds)
            self._buffer = b""
            self.pid = self._message(30)["pid"]  # the launcher forks at once; 30 s bounds a stuck one
        finally:
            for fd in fds:
                os.close(fd)

    def _message(self, timeout):
        """The launcher's next JSON line; subprocess.TimeoutExpired when none comes within `timeout` (None: wait)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        while b"\n" not in self._buffer:  # each turn reads once at least: poll() sees a status already sent
            left = None if deadline is None else max(deadline - time.monotonic(), 0.0)
            self._conn.settimeout(left)  # 0.0: a read that does not wait
            try:
                data = self._conn.recv(4096)
            except (BlockingIOError, TimeoutError, socket.timeout):
                raise subprocess.TimeoutExpired(self.args, timeout) from None
            if not data:
                raise RuntimeError("the tests' app launcher ended before the launch did")
            self._buffer += data
        line, self._buffer = self._buffer.split(b"\n", 1)
        return json.loads(line)

    def _status(self, timeout):
        self.returncode = os.waitstatus_to_exitcode(self._message(timeout)["status"])
        self._conn.close()

    def poll(self):
        if self.returncode is None:
            try:
                self._status(0.0)
            except subprocess.TimeoutExpired:
                pass
        return self.returncode

    def wait(self, timeout=None):
        if self.returncode is None:
            self._status(timeout)
        return self.returncode

    def send_signal(self, sig):
        if self.returncode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def kill(self):
        self.send_signal(signal.SIGKILL)

    def terminate(self):
        self.send_signal(signal.SIGTERM)

    def communicate(self, timeout=None):
        """Both pipes read to their end, then the exit status; subprocess.TimeoutExpired past `timeout`."""
        deadline = None if timeout is None else time.monotonic() + timeout
        if self.stdin is not None and not self.stdin.closed:
            self.stdin.close()
        chunks = {f: [] for f in (self.stdout, self.stderr) if f is not None}
        selector = selectors.DefaultSelector()
        for f in chunks:
            selector.register(f, selectors.EVENT_READ)
        while selector.get_map():
            left = None if deadline is None else deadline - time.monotonic()
            if left is not None and left <= 0:
                raise subprocess.TimeoutExpired(self.args, timeout)
            for key, _ in selector.select(left):
                data = os.read(key.fileobj.fileno(), 1 << 16)
                if data:
                    chunks[key.fileobj].append(data)
                else:
                    selector.unregister(key.fileobj)
        self.wait(None if deadline is None else max(deadline - time.monotonic(), 0.001))
        out = []
        for f in (self.stdout, self.stderr):
            if f is None:
                out.append(None)
                continue
            data = b"".join(chunks[f])
            out.append(data.decode(errors="replace") if "b" not in f.mode else data)
            f.close()
        return tuple(out)


def run_app(args, module="ppo_torchrl", timeout=300, cwd=None, env=None):
    """subprocess.run(capture_output=True) of an app launch; the process is killed past `timeout`."""
    process = App(args, module=module, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        out, err = process.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()
        raise
    return subprocess.CompletedProcess(process.args, process.returncode, out, err)


def launch(argv, cwd=None, env=None, stdin=None, stdout=None, stderr=None, text=True, start_new_session=False,
           fsize=None):
    """An App for an argv as subprocess.Popen takes it ([python, "-m", module, ...] or [python, "-c", code, ...]):
    benchmarks/data_safety.py launches through it when the tests set its LAUNCH."""
    assert argv[0] == sys.executable and argv[1] in ("-m", "-c"), argv
    module, code = (argv[2], None) if argv[1] == "-m" else (None, argv[2])
    return App(argv[3:], module=module, code=code, cwd=cwd, env=env, stdin=stdin, stdout=stdout, stderr=stderr,
               text=text, start_new_session=start_new_session, fsize=fsize)


def run_cli(*args, module="ppo_torchrl", timeout=300, cwd=None):
    return run_app(args, module=module, timeout=timeout, cwd=cwd)


@pytest.fixture(scope="session")
def cli_finished_run(tmp_path_factory):
    """A real finished run (4 iterations, checkpoints every iteration), via the CLI, made once per test worker;
    modules take a copy of it (test_bad_input.finished_run) and never this one."""
    run = tmp_path_factory.mktemp("cli_finished") / "run"
    result = run_cli("env=InvertedPendulum-v4", *TINY, "collector.total_frames=1024", f"hydra.run.dir={run}")
    assert result.returncode == 0, result.stderr[-2000:]
    return run


def ran(main, args, capsys):
    """An entry point's main in-process through the one error path: (exit code, stderr lines); 0 when it returned."""
    from ppo_torchrl.errors import guarded

    try:
        guarded(main, args)
        code = 0
    except SystemExit as exit_:
        code = exit_.code
    return code, [line for line in capsys.readouterr().err.splitlines() if line.strip()]


# The suite's longest tests (`make test ARGS=--durations=20`), started first: with two workers, a long test that
# lands last leaves the other worker idle until it ends. Order only; every test still runs. (Only tests without a
# costly module fixture: moving one out of its module would build that fixture twice.)
LONG_FIRST = (
    "test_data_safety.py::test_the_apps_real_commands",
    "test_legged.py::test_a_legged_run_is_named_by_its_model",
    "test_config_data.py::test_evaluate_export_load_and_evaluate_run_refuse",
    "test_config_data.py::test_resume_refuses",
    "test_reliability.py::test_interrupted_and_resumed_run_matches",
    "test_bad_input.py::test_a_second_process_is_refused",
    "test_envpool.py::test_the_cli_trains",
    "test_playground.py::test_the_cli_trains",
    "test_reliability.py::test_sigint_to_a_training_process",
    "test_workers.py::test_ctrl_c_during_a_workers_run",
    "test_one_pipeline.py::test_a_resume_collects",
)


def pytest_collection_modifyitems(items):
    def rank(item):
        return next((i for i, name in enumerate(LONG_FIRST) if name in item.nodeid), len(LONG_FIRST))

    items.sort(key=rank)
