"""Errors a user can act on, reported as one line and a non-zero exit instead of a traceback."""

from __future__ import annotations

import os
import sys

EXIT_CONFIG = 2  # bad input: config, command line, run dir, checkpoint
EXIT_TRAINING = 3  # training stopped itself (non-finite loss, gradient or parameter)
EXIT_SIGNAL = {2: 130, 15: 143}  # interrupted: 128 + signal number, as shells report it


class ConfigError(ValueError):
    """Bad user input: what was wrong and what is allowed, in one sentence."""


class TrainingError(RuntimeError):
    """Training cannot go on (a non-finite quantity); the last good checkpoint is kept."""


class Interrupted(Exception):
    """SIGINT/SIGTERM: the run saved what it had and stops."""

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.signum = signum


def exit_code(error: BaseException) -> int:
    if isinstance(error, Interrupted):
        return EXIT_SIGNAL.get(error.signum, 128 + error.signum)
    return EXIT_TRAINING if isinstance(error, TrainingError) else EXIT_CONFIG


def report_and_exit(error: BaseException) -> None:
    """Print `error: <message>` on one line; PPO_TORCHRL_DEBUG=1 re-raises for the traceback."""
    if os.environ.get("PPO_TORCHRL_DEBUG"):
        raise error
    message = " ".join(str(error).split())  # one line, whatever the message held
    prefix = "interrupted" if isinstance(error, Interrupted) else "error"
    print(f"{prefix}: {message}", file=sys.stderr, flush=True)
    sys.exit(exit_code(error))
