"""How long a run takes to stop, with its one line, after one of its collector workers is killed (issue 47,
item 4): a 2-worker InvertedPendulum-v4 run, SIGKILL to a worker once the first checkpoint is on disk, the
seconds until the run has exited. Run it beside whatever load you want to judge (e.g. `make test`).

    python benchmarks/dead_worker.py [rounds]
"""

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def one_round() -> float:
    run = Path(tempfile.mkdtemp()) / "run"
    args = ["env=InvertedPendulum-v4", "collector.workers=2", "collector.frames_per_batch=256",
            "collector.total_frames=10000000", "eval.every_frames=0", "checkpoint.every_frames=256", "logger=none",
            "compile=false", f"hydra.run.dir={run}"]
    proc = subprocess.Popen([sys.executable, "-m", "ppo_torchrl", *args], cwd=ROOT, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.time() + 600
        while not (run / "checkpoints" / "last.pt").exists():
            if time.time() > deadline or proc.poll() is not None:
                raise SystemExit(f"no first checkpoint: {proc.poll()=}")
            time.sleep(0.2)
        children = subprocess.run(["ps", "-ww", "-o", "pid=,args=", "--ppid", str(proc.pid)], capture_output=True,
                                  text=True).stdout.splitlines()
        worker = [int(line.split()[0]) for line in children if "resource_tracker" not in line][-1]
        start = time.time()
        os.kill(worker, signal.SIGKILL)
        _, err = proc.communicate(timeout=600)
        took = time.time() - start
        assert proc.returncode == 1 and f"(pid {worker}) died" in err, err[-1000:]
        return took
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        shutil.rmtree(run.parent, ignore_errors=True)


if __name__ == "__main__":
    times = [one_round() for _ in range(int(sys.argv[1]) if len(sys.argv) > 1 else 3)]
    print("seconds from SIGKILL of a worker to the run's exit:", ", ".join(f"{t:.2f}" for t in times))
