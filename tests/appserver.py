"""The tests' app launcher: `python -m <module> ARGS` as a real process of its own, without paying the imports again.

Half of `make test`'s time was interpreter starts: every launch of the app imported torch, torchrl, tensordict, mujoco,
gymnasium and hydra again (about 4-5 s of a core each, about 150 launches). This server imports them once per test
worker, then forks one child per launch. The child is a real process (its own pid, signals, exit status, file
descriptors, locks, children) and runs the module with `runpy.run_module(..., run_name="__main__")`, which is what
`python -m` runs, and it ends through the interpreter's own exit (atexit, flushes, a traceback on an uncaught error).

What a fork cannot give is what a fresh interpreter does at start: interpreter flags (-S, -X importtime) and
environment variables read at import time. A launch whose environment differs from the server's in one of those
(`IMPORT_TIME`) is exec'd as a fresh `python -m` in the forked child, so it still behaves as a plain launch; tests of
the interpreter start itself (startup imports, `-S`) call subprocess directly.

Protocol (one unix socket per test worker): the client sends one JSON line (module, args, cwd, env) with its stdin,
stdout and stderr descriptors (SCM_RIGHTS); the server answers `{"pid": N}` once the child is forked and
`{"status": S}` (a wait status) when it has ended. The server is single-threaded, never runs torch code, and ends
when its parent (the test worker) ends or is gone, killing the launches still running.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import socket
import sys

# Read by a fresh interpreter (or by a library's import) at start: a launch that sets one differently is exec'd.
IMPORT_TIME = ("MUJOCO_GL", "PYOPENGL_PLATFORM", "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
               "MKL_NUM_THREADS", "PYTHONPATH", "PYTHONHOME", "PYTHONSAFEPATH", "PYTHONNOUSERSITE", "PYTHONDONTWRITEBYTECODE",
               "PYTHONOPTIMIZE", "PYTHONDEVMODE", "PYTHONUTF8", "PYTHONIOENCODING", "PYTHONUNBUFFERED",
               "PYTHONFAULTHANDLER", "PYTHONMALLOC", "TORCH_LOGS", "TORCHDYNAMO_DISABLE", "LD_PRELOAD")


SET_BY_IMPORT: dict[str, str] = {}  # what the imports below set in os.environ (ppo_torchrl's setdefaults)


def _preimport():
    before = dict(os.environ)
    import ppo_torchrl  # noqa: F401  (sets MUJOCO_GL and OPENBLAS_NUM_THREADS defaults as any launch does)
    import ppo_torchrl.__main__  # noqa: F401
    import ppo_torchrl.envs.make  # noqa: F401
    import ppo_torchrl.evaluate  # noqa: F401
    import ppo_torchrl.export  # noqa: F401
    import ppo_torchrl.records  # noqa: F401
    import ppo_torchrl.report  # noqa: F401
    import ppo_torchrl.trainer  # noqa: F401

    SET_BY_IMPORT.update({k: v for k, v in os.environ.items() if k not in before})


def _fresh_start_needed(env: dict) -> bool:
    """True when a fresh interpreter would start differently from this one under `env`."""
    if env.get("PYTHONWARNINGS", "ignore") != "ignore":  # the server runs with none; "ignore" is set in the child
        return True
    return any(env.get(name, SET_BY_IMPORT.get(name)) != os.environ.get(name) for name in IMPORT_TIME)


def _child(request: dict, fds: list[int]):
    """In the forked child: become the launch. Returns (module, code, args) for the top level to run."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for target, fd in enumerate(fds):
        os.dup2(fd, target)
    for fd in fds:
        if fd > 2:
            os.close(fd)
    os.chdir(request["cwd"])
    env = request["env"]
    if request.get("fsize") is not None:
        import resource

        resource.setrlimit(resource.RLIMIT_FSIZE, (request["fsize"], request["fsize"]))
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    how = ["-c", request["code"]] if request.get("code") is not None else ["-m", request["module"]]
    if _fresh_start_needed(env):
        if request.get("new_session"):
            os.setsid()
        os.execve(sys.executable, [sys.executable, *how, *request["args"]], env)
    os.environ.clear()
    os.environ.update({**SET_BY_IMPORT, **env})  # as a fresh start's imports would leave it
    if env.get("PYTHONWARNINGS") == "ignore":
        import warnings

        warnings.simplefilter("ignore")
    if request.get("new_session"):
        os.setsid()
    if request.get("code") is not None:
        sys.path[0] = ""  # as `python -c` has it
        return None, request["code"], request["args"]
    sys.path[0] = os.getcwd()  # `python -m` puts the working directory first
    for name in (request["module"], request["module"] + ".__main__"):  # run fresh as __main__, as `python -m` does
        sys.modules.pop(name, None)  # (runpy warns of a module it finds imported already)
    return request["module"], None, request["args"]


def serve(path: str):
    """Accept launches until the parent is gone; returns (module, code, args) in a forked child."""
    parent = os.getppid()
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)
    listener.listen(16)
    waiting: dict[int, socket.socket] = {}
    selector = selectors.DefaultSelector()
    selector.register(listener, selectors.EVENT_READ)
    ended = []
    signal.signal(signal.SIGTERM, lambda *_: ended.append(True))  # the worker's exit: end and take the launches along
    print("ready", flush=True)
    while os.getppid() == parent and not ended:
        for _ in selector.select(timeout=0.05):
            conn, _ = listener.accept()
            conn.settimeout(10)  # a client that stalls mid-request is dropped, never waited on for good
            fds = []
            try:
                data, fds, _, _ = socket.recv_fds(conn, 1 << 20, 3)
                while data and not data.endswith(b"\n"):
                    more = conn.recv(1 << 20)
                    data = data + more if more else b""  # the client went away mid-request
                request = json.loads(data) if data else None
            except (OSError, ValueError):
                request = None
            if request is None or len(fds) != 3:
                for fd in fds:
                    os.close(fd)
                conn.close()
                continue
            sys.stdout.flush()
            sys.stderr.flush()
            pid = os.fork()
            if pid == 0:
                selector.close()
                listener.close()
                for other in waiting.values():
                    other.close()
                conn.close()
                return _child(request, fds)
            for fd in fds:
                os.close(fd)
            try:
                conn.sendall(json.dumps({"pid": pid}).encode() + b"\n")
            except OSError:
                pass
            waiting[pid] = conn
        while waiting:
            try:
                pid, status = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                break
            if pid == 0:
                break
            conn = waiting.pop(pid, None)
            if conn is not None:
                try:
                    conn.sendall(json.dumps({"status": status}).encode() + b"\n")
                except OSError:
                    pass
                conn.close()
    for pid in waiting:  # a launch a failed test left running does not outlive the test worker
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    sys.exit(0)


def _run(module, code, args):
    if code is not None:  # as `python -c`: the code is module __main__'s, a fresh one
        import types

        sys.argv = ["-c", *args]
        main = sys.modules["__main__"] = types.ModuleType("__main__")
        main.__builtins__ = __builtins__
        exec(compile(code, "<string>", "exec"), main.__dict__)
    else:
        import runpy

        sys.argv = [sys.argv[0], *args]
        runpy.run_module(module, run_name="__main__", alter_sys=True)


def _finish():
    """The interpreter's exit up to its module teardown, which is all that is left out: it frees ~2,600 modules and
    takes ~0.9 s of a core with torch loaded, for nothing a launch can observe (Py_FinalizeEx's order: the non-daemon
    threads joined, the atexit callbacks, the standard streams flushed). The only private calls of this file."""
    import atexit
    import threading

    threading._shutdown()
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass


def _exit(status: int):
    _finish()
    os._exit(status)


if __name__ == "__main__":
    _preimport()
    launch = serve(sys.argv[1])
    try:
        _run(*launch)
    except SystemExit as exit_:  # as the interpreter reads it: None 0, an int itself, anything else printed, 1
        if exit_.code is None or isinstance(exit_.code, int):
            _exit(exit_.code or 0)
        print(exit_.code, file=sys.stderr)
        _exit(1)
    except KeyboardInterrupt:  # uncaught: the traceback, then the process ends by SIGINT, as the interpreter's does
        import traceback

        traceback.print_exc()
        _finish()
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGINT)
    except BaseException:  # noqa: B902 (uncaught: the traceback, exit 1)
        sys.excepthook(*sys.exc_info())
        _exit(1)
    _exit(0)
