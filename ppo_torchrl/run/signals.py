"""SIGINT / SIGTERM at any moment of a run end in one line that says what is on disk.

- From process start (`install()`), a signal interrupts whatever runs (an import, env building,
  compile) and the entry point's error path reports it: exit 130 (SIGINT) or 143 (SIGTERM).
- In the training loop (`StopRequest`), the first signal asks the loop to stop after the current
  iteration, which then saves a checkpoint; a second one abandons the iteration at once. The last
  iteration is no different, and during the final eval (after its checkpoint is saved) one signal stops at once.
Either way the line is built from `ON_DISK`, which the trainer updates as it saves, so it never
claims a checkpoint that is not there.
"""

from __future__ import annotations

import os
import shlex
import signal
import sys
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

SIGNALS = (signal.SIGINT, signal.SIGTERM)


@dataclass
class OnDisk:
    run_dir: Optional[Path] = None
    checkpoint: Optional[Path] = None  # the newest checkpoint this run has on disk
    checkpoint_frames: int = 0
    frames: int = 0  # frames trained so far
    total_frames: Optional[int] = None  # the run's budget: a checkpoint at it has nothing left to resume
    started: bool = False  # the run dir holds this run (set up without error and committed)

    def describe(self) -> str:
        if self.checkpoint is not None:
            done = self.total_frames is not None and self.checkpoint_frames >= self.total_frames
            run = shlex.quote(str(self.run_dir))
            then = (f"every frame is trained; python -m ppo_torchrl resume={run} runs the final eval and marks the "
                    "run finished" if done else f"resume with: python -m ppo_torchrl resume={run}")
            return f"the last checkpoint on disk is {self.checkpoint} at frame {self.checkpoint_frames} ({then})"
        # a run stopped before it started leaves no dir (Lifecycle.rollback): nothing to overwrite then
        again = f"; to start again in {self.run_dir} add overwrite=true" if self.run_dir and self.started else ""
        if self.frames:
            return f"nothing was saved: the run had done {self.frames} frames and no checkpoint yet{again}"
        return f"nothing was saved{again}"


ON_DISK = OnDisk()


class Interrupt(KeyboardInterrupt):
    """A signal turned into an exception; `signum` sets the exit code (128 + signum)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _interrupt(signum, frame) -> None:
    raise Interrupt(signum)


def _exit_during_startup(signum, frame) -> None:
    print("interrupted: stopped at once during start-up; nothing was saved", file=sys.stderr, flush=True)
    os._exit(128 + signum)


def install_for_startup() -> None:
    """`python -m ppo_torchrl[.entry]`: a signal while the modules import exits at once with one line
    (nothing is open or written yet); each entry point then calls `install()`."""
    if threading.current_thread() is threading.main_thread():
        for signum in SIGNALS:
            signal.signal(signum, _exit_during_startup)


def install() -> None:
    """Signals raise `Interrupt` (SIGTERM too, whose default would end the process silently)."""
    if threading.current_thread() is threading.main_thread():
        for signum in SIGNALS:
            signal.signal(signum, _interrupt)


def ignore_from_now() -> None:
    """A command's work is done and its last line printed: a signal from here to the process's end (Python's own
    shutdown, joining threads) would only print Python's "Exception ignored ... KeyboardInterrupt" traceback."""
    if threading.current_thread() is threading.main_thread():
        for signum in SIGNALS:
            signal.signal(signum, signal.SIG_IGN)


class StopRequest:
    """The loop's handlers: the first signal sets `signum` (stop after this iteration and save),
    a second one raises `Interrupt` at once."""

    def __init__(self):
        self.signum: Optional[int] = None
        self.at_once = False  # set around work that ends the run anyway (the final eval): no iteration to finish
        self._previous = {}

    def __enter__(self) -> "StopRequest":
        if threading.current_thread() is threading.main_thread():
            for signum in SIGNALS:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        if self.signum is not None or self.at_once:
            raise Interrupt(signum)
        self.signum = signum
        print(f"{signal.Signals(signum).name}: stopping after this iteration to save a checkpoint "
              "(send it again to stop at once)", file=sys.stderr, flush=True)

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
