"""The one module that reads or writes what a library does not publish, and why (Gymnasium's `TimeLimit`
counter, for a bit-exact resume, stays in positions.py with the rest of an env's position).

TorchRL's collectors:
- The layout of a collector's `state_dict()`: in one process, the collector's own (`env_state_dict`: the
  env's transforms' state, `frames`, `iter`, ...); `MultiSyncCollector`: `{"worker0": <that>, "worker1": ...}`;
  `RayCollector`: a list of them. TorchRL has no accessor for one worker's env state, and the statistics of
  several workers are pooled between batches (collection.py), so the app reads and rewrites `EnvState`'s one
  entry in each part (`worker_parts`, `env_snapshot`, `shared_part`, `with_worker_parts`), found under the key
  PyTorch gives a module's `get_extra_state` (`<module name>._extra_state`, `env_state_key`; asking
  `state_dict()` for its keys instead fails on a lazy transform's uninitialized buffer, e.g. CatFrames').
- `Collector.load_state_dict` sets `_frames` / `_iter` from the state it loads: a state pushed to a worker
  between batches carries the worker's own (`keep_counters`).
- `MultiSyncCollector.procs`: the worker processes, whose sentinels `WorkerWatch` waits on (no accessor).
- Whether this run started the local Ray instance it shuts down: an attribute set on the `RayCollector`.

Hydra's Optuna sweeper: the search space a command's `key=choice(...)` overrides make, as the sweeper makes it
(`_impl.create_params_from_overrides`), so a stored study is checked against the command before a trial runs.

EnvPool's renderer (envs_playground.py films a Playground task with `pool.render()`): it draws into the OpenGL
context current in the calling thread, and makes one itself only on Windows (envpool/python/envpool.py,
`_ensure_platform_render_context`); elsewhere it fails with "an OpenGL platform library has not been loaded"
unless one is current. `gl_context` makes one with MuJoCo's public `mujoco.GLContext` (headless: MUJOCO_GL=egl).

TorchRL's `CSVLogger`: its files (`logs/<name>/scalars/<key>.csv`, rows `step,value`), whose rows past a
checkpoint a resume drops.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

from ppo_torchrl.envs.state import PACKED, EnvState, pack, unpack

OWN = "fast"  # a collector's own entry in its state (its RNG); first FastCollector's, hence the name


def env_state_key(env) -> str:
    """The key of EnvState's extra state in `env.transform.state_dict()` (an env of envs.make_torchrl_env)."""
    for name, module in env.transform.named_modules():
        if isinstance(module, EnvState):
            return f"{name}._extra_state" if name else "_extra_state"
    raise TypeError("not an env of envs.make_torchrl_env (no EnvState transform)")


def worker_parts(whole) -> list:
    """Each collector's part of a collector state, opened (FastCollector's is one pickled entry): a
    MultiSyncCollector's {"worker0": ..., "frames": ...}, a RayCollector's list, one process's state itself."""
    if isinstance(whole, (list, tuple)):
        parts = list(whole)
    elif "worker0" in whole:
        parts = [whole[f"worker{i}"] for i in range(sum(key.startswith("worker") for key in whole))]
    else:
        parts = [whole]
    return [_open(part) for part in parts]


def with_worker_parts(whole, parts: list):
    """`whole` (a collector state) with each part replaced, each in the form its part had (packed or not)."""
    old = whole if isinstance(whole, (list, tuple)) else \
        [whole[f"worker{i}"] for i in range(len(parts))] if "worker0" in whole else [whole]
    parts = [pack(p) if PACKED in dict(o) else p for p, o in zip(parts, old)]
    if isinstance(whole, (list, tuple)):
        return parts
    return {**whole, **{f"worker{i}": p for i, p in enumerate(parts)}} if "worker0" in whole else parts[0]


def _open(part) -> dict:
    return unpack(part) or dict(part)  # FastCollector's is one pickled entry (env_state.pack)


def env_snapshot(part: dict, key: str) -> Optional[dict]:
    """EnvState's snapshot in one collector's (opened) state."""
    return unpack((part.get("env_state_dict") or {}).get(key))


def shared_part(part: dict, key: str, snapshot: dict) -> dict:
    """What a collector whose (opened) state is `part` loads between batches: EnvState's `snapshot` in place of
    its own, and nothing of the collector's own state (OWN: FastCollector's RNG), so
    each env goes on from where it is."""
    part = {k: v for k, v in part.items() if k != OWN}
    return {**part, "env_state_dict": {**dict(part["env_state_dict"]), key: pack(snapshot)}}


def keep_counters(collector, state: dict) -> dict:
    """A state for `Collector.load_state_dict` that leaves the collector's frame and iteration counters as they
    are (the trainer counts frames; TorchRL's Collector sets its private counters from the state it loads)."""
    return {**state, "frames": collector._frames, "iter": collector._iter}


def worker_processes(collector) -> list:
    """A multi-process collector's worker processes ([] for Ray or one process)."""
    return list(getattr(collector, "procs", None) or [])


def mark_started_ray(collector, started: bool) -> None:
    collector._ppo_started_ray = started


def started_ray(collector) -> bool:
    return bool(getattr(collector, "_ppo_started_ray", False))


def optuna_space(overrides: list) -> dict:
    """The Optuna distributions of `key=choice(...)` / `interval(...)` overrides, as Hydra's Optuna sweeper
    builds them."""
    from hydra_plugins.hydra_optuna_sweeper._impl import create_params_from_overrides

    return create_params_from_overrides(overrides)[0]


_GL_CONTEXTS: dict = {}  # thread id -> the mujoco.GLContext made current there (kept alive: EnvPool draws into it)


def gl_context(width: int, height: int) -> None:
    """An OpenGL context current in this thread for EnvPool's renderer (module doc), made once per thread."""
    import threading

    import mujoco

    key = threading.get_ident()
    if key not in _GL_CONTEXTS:
        context = mujoco.GLContext(max(width, 640), max(height, 480))
        context.make_current()
        _GL_CONTEXTS[key] = context


def csv_logger_files(run_dir: Path) -> list:
    """The scalar files TorchRL's CSVLogger writes under a run dir (rows: step,value)."""
    return sorted((Path(run_dir) / "logs").glob("*/scalars/**/*.csv"))
