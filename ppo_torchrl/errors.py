"""One error path for every entry point: one line on stderr and an exit code of the error's kind.

| kind | exit | line |
|---|---|---|
| bad input (`ConfigError`): config, command line, run dir, checkpoint | 2 | `error: ...` |
| training stopped itself (`TrainingError`: a non-finite loss, gradient or parameter) | 3 | `error: ...` |
| the machine, not the input (`EnvironmentFault`, or an OSError such as a full disk or no permission) | 1 | `error: ...` |
| SIGINT / SIGTERM (`Interrupted`, or a signal at any other moment, also one a library wrapped) | 130 / 143 | `interrupted: ...` |
| anything else: a bug | 1 | `error: internal error ...; please report it` + the traceback in a log file |

`PPO_TORCHRL_DEBUG=1` also prints the traceback; the exit code stays the same.
"""

from __future__ import annotations

import errno
import os
import sys
import tempfile
import traceback

EXIT_CONFIG = 2  # bad input: config, command line, run dir, checkpoint
EXIT_TRAINING = 3  # training stopped itself (non-finite loss, gradient or parameter)
EXIT_BUG = 1  # an internal error: please report
EXIT_ENVIRONMENT = 1  # the machine: a full disk, no permission, no file locks, a helper process killed
# OSErrors a user fixes (space, permissions, paths), not bugs: one line naming the path, exit 1.
USER_FIXABLE = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is used up",
                errno.EFBIG: "a file reached the file size limit", errno.EACCES: None,
                errno.EPERM: None, errno.EROFS: None, errno.ENOTDIR: None, errno.EISDIR: None,
                errno.ENAMETOOLONG: None, errno.ENOLCK: None, errno.ELOOP: None}
EXIT_SIGNAL = {2: 130, 15: 143}  # interrupted: 128 + signal number, as shells report it


class ConfigError(ValueError):
    """Bad user input: what was wrong and what is allowed, in one sentence."""


class TrainingError(RuntimeError):
    """Training cannot go on (a non-finite quantity); the last good checkpoint is kept."""


class EnvironmentFault(RuntimeError):
    """The machine, not the input: an unwritable dir, a filesystem without locks, a helper process killed."""


class Interrupted(Exception):
    """SIGINT/SIGTERM: the run saved what it had and stops."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.signum = signum


def signal_in_chain(error: BaseException):
    """A KeyboardInterrupt (a signal) that a library turned into another error while importing or starting
    (torch's and others' `except Exception: raise ImportError(...)`), or None."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, (KeyboardInterrupt, Interrupted)):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def _user_fixable_os_error(error: BaseException):
    return error if isinstance(error, OSError) and error.errno in USER_FIXABLE else None


def exit_code(error: BaseException) -> int:
    error = signal_in_chain(error) or error
    if isinstance(error, (Interrupted, KeyboardInterrupt)):
        signum = getattr(error, "signum", 2)
        return EXIT_SIGNAL.get(signum, 128 + signum)
    if isinstance(error, TrainingError):
        return EXIT_TRAINING
    if isinstance(error, EnvironmentFault) or _user_fixable_os_error(error):
        return EXIT_ENVIRONMENT
    return EXIT_CONFIG if isinstance(error, ConfigError) else EXIT_BUG


def message_of(error: BaseException) -> str:
    """The one line for an error (an internal one also gets its traceback written to a log)."""
    from ppo_torchrl.run.signals import ON_DISK

    error = signal_in_chain(error) or error
    if isinstance(error, KeyboardInterrupt):  # a signal outside the training loop
        return f"interrupted: stopped at once; {ON_DISK.describe()}"
    if isinstance(error, Interrupted):
        return f"interrupted: {error}"
    if isinstance(error, (ConfigError, TrainingError, EnvironmentFault)):
        return f"error: {error}"
    if _user_fixable_os_error(error):
        what = USER_FIXABLE[error.errno] or error.strerror
        where = f" writing {error.filename}" if error.filename else ""
        todo = ("free some space (or pick another dir)" if error.errno in (errno.ENOSPC, errno.EDQUOT)
                else "raise the limit (ulimit -f)" if error.errno == errno.EFBIG
                else "fix the path or its permissions (or pick another path)")
        return f"error: {what}{where}; {todo}, then run it again"
    log = write_traceback(error, ON_DISK.run_dir if ON_DISK.started else None)  # a dir not yet kept is rolled back
    first = str(error).strip().splitlines()[0] if str(error).strip() else ""
    return (f"error: internal error ({type(error).__name__}{': ' + first if first else ''}); please report it "
            f"with the traceback in {log}")


def write_traceback(error: BaseException, run_dir) -> str:
    text = "".join(traceback.format_exception(type(error), error, error.__traceback__))
    try:
        if run_dir is not None and os.path.isdir(run_dir):
            path = os.path.join(run_dir, "error.log")
            with open(path, "a") as f:
                f.write(text)
            return path
    except OSError:
        pass
    try:
        fd, path = tempfile.mkstemp(prefix="ppo_torchrl_error_", suffix=".log")
        with os.fdopen(fd, "w") as f:
            f.write(text)
    except OSError as exc:  # nowhere to write it (a full disk): still one line
        return f"the output of PPO_TORCHRL_DEBUG=1 (no log file could be written: {exc.strerror or exc})"
    return path


def report_and_exit(error: BaseException) -> None:
    """Print the error's line (and with PPO_TORCHRL_DEBUG=1 its traceback), exit with its code."""
    if os.environ.get("PPO_TORCHRL_DEBUG"):
        traceback.print_exception(type(error), error, error.__traceback__, file=sys.stderr)
    line = " ".join(message_of(error).split())  # one line, whatever the message held
    print(line, file=sys.stderr, flush=True)
    sys.exit(exit_code(error))


def guarded(function, *args):
    """Run an entry point; whatever escapes it ends through `report_and_exit`."""
    try:
        return function(*args)
    except SystemExit:
        raise
    except BaseException as error:  # noqa: BLE001 - the one place every error is reported
        report_and_exit(error)
