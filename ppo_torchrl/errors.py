"""Errors a user can fix, reported as one line and a non-zero exit instead of a traceback."""

from __future__ import annotations

import os
import sys


class ConfigError(ValueError):
    """Bad user input: what was wrong and what is allowed, in one sentence."""


def report_and_exit(error: BaseException, code: int = 2) -> None:
    """Print `error: <message>` on one line; PPO_TORCHRL_DEBUG=1 re-raises for the traceback."""
    if os.environ.get("PPO_TORCHRL_DEBUG"):
        raise error
    message = " ".join(str(error).split())  # one line, whatever the message held
    print(f"error: {message}", file=sys.stderr, flush=True)
    sys.exit(code)
