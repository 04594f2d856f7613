"""The workers' message costs on a live run: `state_dict()` / `load_state_dict()` round trips, the weights
sent before a batch and the statistics' merge after it, in ms (10 each, after 2 batches).

    .venv/bin/python benchmarks/roundtrip.py [env=Hopper-v4] [collector.workers=2] ...
"""

import sys
import tempfile
import time
import warnings
from pathlib import Path

warnings.filterwarnings("ignore")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from conftest import compose_config  # noqa: E402
from ppo_torchrl.trainer import Trainer  # noqa: E402


def timed(name: str, call, n: int = 10):
    times, out = [], None
    for _ in range(n):
        t0 = time.perf_counter()
        out = call()
        times.append((time.perf_counter() - t0) * 1e3)
    print(f"{name:16s}", " ".join(f"{t:.1f}" for t in times), flush=True)
    return out


def main() -> None:
    cfg = compose_config(["eval.every_frames=0", "eval.final_episodes=0", "logger=none", "checkpoint.every_frames=0",
                          "env=Hopper-v4", "collector.workers=2", *sys.argv[1:]])
    with tempfile.TemporaryDirectory() as run_dir:
        collection = Trainer(cfg, Path(run_dir)).collector
        try:
            collection.collect()
            collection.collect()
            collector = collection.collector
            state = timed("state_dict", collector.state_dict)
            timed("load_state_dict", lambda: collector.load_state_dict(state))
            timed("weights", collector.update_policy_weights_)
            timed("merge", collection._merge_stats)
        finally:
            collection.close()


if __name__ == "__main__":
    main()
