"""Reference trajectories of the locomotion env before the rebuild (robots/env.py: Ant-v5's class with its mixins), which
the batched legged env (tasks/locomotion/batch.py) was shown to step bit for bit (issue 72): recorded once, so that the
equality tests hold the batch to that env after it is gone.

    python tests/legged_reference.py   # writes tests/data/legged_reference.npz and legged_reference_models.json

It runs only on a checkout that still has robots/env.py: f73badb, the commit that added this file (`git worktree add
<dir> f73badb`, then this script there; robots/env.py went in the commit after the tests stopped needing it). Each case steps the old env
under fixed actions (a seeded normal draw, clipped to [-1, 1]) for a fixed number of control steps, resetting it where
an episode ends, and keeps what a platform cannot change and what a test needs to compare to tolerance: a digest of
the physics state (qpos and qvel bytes: MuJoCo's arithmetic, no NumPy) after every step and reset, every reward, each
reward term's sum, the observation's sum per step and the whole observation every 100 steps, the steps that ended an
episode and why. NumPy's transcendental functions may differ by an ulp between CPUs, so only the physics is compared
bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
DATA, MODELS = HERE / "data" / "legged_reference.npz", HERE / "data" / "legged_reference_models.json"
GO1, ANYMAL = "menagerie/unitree_go1/scene.xml", "menagerie/anybotics_anymal_b/scene.xml"
EVERY_TERM = ["env.legged.stumble_cost_weight=2.0", "env.locomotion.feet_air_time_weight=0.3",
              "env.locomotion.joint_speed_limit=20.0", "env.locomotion.joint_speed_limit_cost_weight=0.05",
              "env.locomotion.torque_limit=30.0"]
# case -> (overrides, control steps, seed)
CASES = {
    "go1": (["experiment=legged_trot_v2", f"env.xml_file={GO1}"], 2000, 5),
    "anymal_b": (["experiment=legged_trot_v2", f"env.xml_file={ANYMAL}"], 2000, 5),
    "go1_every_term": (["experiment=legged_trot_v2", f"env.xml_file={GO1}", *EVERY_TERM], 600, 3),
    "anymal_b_issue46": (["experiment=legged_trot", f"env.xml_file={ANYMAL}"], 600, 4),
    "quadruped_climb": (["experiment=quadruped_climb"], 600, 2),
}
SCALE = 0.3
EVERY = 100  # the whole observation every EVERY steps


def actions(seed: int, steps: int, nu: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([(SCALE * rng.standard_normal(nu)).clip(-1, 1).astype(np.float32) for _ in range(steps)])


def physics_digest(data) -> int:
    return int.from_bytes(hashlib.sha1(data.qpos.tobytes() + data.qvel.tobytes()).digest()[:8], "little", signed=True)


def model_digests(model) -> dict:
    fields = [f for f in dir(model) if not f.startswith("_") and isinstance(getattr(model, f, None), np.ndarray)]
    return {f: hashlib.sha1(np.ascontiguousarray(getattr(model, f)).tobytes()).hexdigest()[:16] for f in fields}


def record(overrides, steps: int, seed: int) -> dict:
    from conftest import compose_config
    from ppo_torchrl.envs.make import make_gym_env

    env = make_gym_env(compose_config(overrides).env)
    data = env.unwrapped.data
    obs, _ = env.reset(seed=seed)
    acts = actions(seed, steps, env.unwrapped.model.nu)
    out = {"digest": [], "reset_digest": [], "reward": [], "obs_sum": [], "obs": [obs], "ended": [], "why": [],
           "reset_obs_sum": []}
    sums: dict = {}
    for t, action in enumerate(acts):
        obs, reward, term, trunc, info = env.step(action)
        out["digest"].append(physics_digest(data))
        out["reward"].append(reward)
        out["obs_sum"].append(obs.sum())
        for key, value in info.items():
            if key.startswith("reward_"):
                sums[key[len("reward_"):]] = sums.get(key[len("reward_"):], 0.0) + float(value)
        if (t + 1) % EVERY == 0:
            out["obs"].append(obs)
        if term or trunc:
            out["ended"].append([t, int(term), int(trunc)])
            out["why"].append(str(info.get("termination")))
            obs, _ = env.reset()
            out["reset_digest"].append(physics_digest(data))
            out["reset_obs_sum"].append(obs.sum())
    env.close()
    arrays = {k: np.asarray(v) for k, v in out.items() if k != "why"}
    arrays["ended"] = arrays["ended"].reshape(-1, 3).astype(np.int64)
    arrays["terms"] = np.array(sorted(sums))
    arrays["term_sums"] = np.array([sums[k] for k in sorted(sums)])
    arrays["why"] = np.array(out["why"])
    return arrays


def main() -> None:
    sys.path.insert(0, str(HERE))
    from conftest import compose_config
    from ppo_torchrl.envs.make import make_gym_env

    everything = {}
    for case, (overrides, steps, seed) in CASES.items():
        for key, value in record(overrides, steps, seed).items():
            everything[f"{case}/{key}"] = value
        print(case, "recorded")
    DATA.parent.mkdir(exist_ok=True)
    np.savez_compressed(DATA, **everything)
    model = make_gym_env(compose_config(CASES["go1"][0]).env).unwrapped.model
    MODELS.write_text(json.dumps({"go1": model_digests(model)}, indent=0, sort_keys=True) + "\n")


if __name__ == "__main__":
    main()
