"""A Ctrl-C at any instant of a command's start-up: N launches of `python -m ppo_torchrl.report --help`, each sent
SIGINT at a random instant of its first `--within` ms; counts the outcomes the data-safety property accepts
(exit 0, 130 with the start-up line, killed by SIGINT) and those it does not (a traceback with exit 1: Python's
own start-up swallowed the KeyboardInterrupt before any of the app's code ran).

    python benchmarks/startup_sigint.py --launches 200 --within 80
"""

from __future__ import annotations

import argparse
import collections
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--launches", type=int, default=200)
    parser.add_argument("--within", type=float, default=80.0, help="ms")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng, outcomes = random.Random(args.seed), collections.Counter()
    for _ in range(args.launches):
        proc = subprocess.Popen([sys.executable, "-m", "ppo_torchrl.report", "--help"], cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(rng.uniform(0, args.within) / 1000)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        code = proc.returncode
        fine = code in (0, 130, -signal.SIGINT) and ("Traceback" not in err or code == -signal.SIGINT)
        outcomes[("accepted" if fine else "traceback") + f" (exit {code})"] += 1
    print(f"{args.launches} launches, SIGINT within {args.within:g} ms: {dict(sorted(outcomes.items()))}")


if __name__ == "__main__":
    main()
