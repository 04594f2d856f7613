"""The data-safety property's round-6 parts (issue 76 item 3), used by data_safety.py: the Python API's entry points
as real commands (ppo_torchrl.train / load / evaluate_run in a script, through the app's one error path as a user's
script would end), and crafted checkpoints: a copy of a real run whose checkpoints carry a payload that would delete
or empty a user's file if anything of it ran (a saved config naming a call, as tests/test_config_data.py crafts them,
or a pickle that asks for os.remove), read by a random entry point (READERS). (`records` is drawn in data_safety.py's
two modes: the command under its run's lock, its record listed in the run's manifest, so overwrite=true still takes
the run whole.)"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

# One API call in its own process: argv = kind, run dir, overrides...; its end as the app's entry points end theirs.
API = r'''
import sys
import numpy as np
import ppo_torchrl
from ppo_torchrl.errors import guarded
from ppo_torchrl.run.signals import ignore_from_now
kind, d, overrides = sys.argv[1], sys.argv[2], sys.argv[3:]
def call():
    if kind in ("api_train", "api_overwrite"):
        ppo_torchrl.train(overrides, run_dir=d, overwrite=kind == "api_overwrite")
    elif kind == "api_resume":
        ppo_torchrl.train(["collector.total_frames=4096"], resume=d)
    elif kind == "api_load":
        policy = ppo_torchrl.load(d)
        policy.predict(np.zeros(policy.obs_dim))
    else:  # api_evaluate
        ppo_torchrl.evaluate_run(d, episodes=2)
try:
    guarded(call)
finally:
    ignore_from_now()
'''
API_KINDS = ("api_train", "api_overwrite", "api_resume", "api_load", "api_evaluate")
API_NESTED = ("api_resume", "api_load", "api_evaluate")  # these also go to a sweep's job or a trial's seed run


def api_argv(kind: str, run: Path, tiny: list) -> list:
    """The interpreter's arguments of one API call (data_safety.REAL's form: what follows `python`)."""
    return ["-c", API, kind, str(run), *tiny]


PAYLOADS = ("unlink", "torch.load via ${resume}", "open nested in CatFrames", "pickle")
READERS = ("evaluate", "export", "resume", "api_load", "api_evaluate", "api_resume", "init_from")


class Remove:
    """A pickle that asks for os.remove(path) when it is loaded (what torch.load(weights_only=False) would run)."""

    def __init__(self, path: str):
        self.path = path

    def __reduce__(self):
        return os.remove, (self.path,)


def craft(source: Path, copy: Path, payload: str, victim: Path) -> None:
    """`copy`: the run dir `source` copied, its checkpoints carrying `payload` aimed at the user's file `victim`."""
    import torch

    from ppo_torchrl.run import checkpoint

    shutil.copytree(source, copy, symlinks=True)
    extra = {"unlink": [{"_target_": "pathlib.Path.unlink", "self": str(victim)}],
             "torch.load via ${resume}": [{"_target_": "torch.load", "f": "${resume}/notes.pt", "weights_only": False}],
             "open nested in CatFrames": [{"_target_": "torchrl.envs.CatFrames", "N": 2, "dim": -1,
                                           "in_keys": {"_target_": "builtins.open", "file": str(victim), "mode": "w"}}],
             }.get(payload)
    torch.save({"notes": Remove(str(victim))}, copy / "notes.pt")  # what ${resume}/notes.pt would load
    for path in (copy / "checkpoints").glob("*.pt"):
        if payload == "pickle":
            torch.save({"actor": Remove(str(victim)), "frames": 0}, path)
            continue
        state = checkpoint.load(path)
        state["config"]["env"]["transforms"]["extra"] = extra
        checkpoint.save(path, state)


def crafted_case(tree, rng, real, ds) -> tuple:
    """A copy of a real run whose checkpoints carry a payload aimed at a user's file (`craft`), read by a random entry
    point (READERS), cut at random or let finish; the user's file must stay whole (the sequence's tree.lost) and the
    command end explained: refused in one line, or (init_from=) trained from the weights alone. `ds`: data_safety."""
    source = ds.targets(tree.root, rng.choice(ds.RUNS), "evaluate", rng)
    if not (source / "checkpoints" / "last.pt").is_file():
        return f"crafted: {source.relative_to(tree.root)} has no checkpoint to craft", []
    victim = tree.root / rng.choice([rel for rel in sorted(tree.files) if (tree.root / rel).is_file()])
    copy, payload, reader = tree.root / f"crafted{rng.randrange(10**6)}", rng.choice(PAYLOADS), rng.choice(READERS)
    craft(source, copy, payload, victim)
    code, err = ds.app(reader, copy, rng, real)
    what = (f"crafted {copy.name} ({payload}, at {victim.relative_to(tree.root)}, from {source.relative_to(tree.root)}) "
            f"{reader} -> {code} {ds.said(err)}")
    return what, ds.checked(f"crafted {reader}", code, err)
