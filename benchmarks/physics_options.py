"""How fast the batched legged env's physics steps under other solver options of the same model (a lead, 2026-12-03).

    .venv/bin/python benchmarks/physics_options.py [menagerie folder, default unitree_go1]

Builds experiment=legged_joystick's env (16 rows, one physics thread) through a Trainer, as benchmarks/legged_speed.py
does, then times the env's own physics step (`_physics`: the rows' mj_step, nothing around it) over 150 control steps
of random actions (half the action range) per variant, three rounds interleaved so that load beside moves them alike.
Variants change `model.opt` of every row: the model's own (Menagerie: elliptic cone, impratio 100, Newton, 100 / 50
iterations), a pyramidal cone, fewer solver iterations, both. Prints control steps/s, contacts per row and the solver
iterations used; MuJoCo's instability warnings (printed by MuJoCo) show which variants do not hold together.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from ppo_torchrl.compose import compose  # noqa: E402
from ppo_torchrl.trainer import Trainer  # noqa: E402

PYRAMIDAL = mujoco.mjtCone.mjCONE_PYRAMIDAL
VARIANTS = {
    "model's own": {},
    "pyramidal": {"cone": PYRAMIDAL},
    "iterations 4, ls 5": {"iterations": 4, "ls_iterations": 5},
    "pyramidal, iterations 4, ls 5": {"cone": PYRAMIDAL, "iterations": 4, "ls_iterations": 5},
    "iterations 2, ls 4": {"iterations": 2, "ls_iterations": 4},
}
STEPS, ROUNDS, ROWS = 150, 3, 16


def main(folder: str = "unitree_go1") -> None:
    cfg = compose(["experiment=legged_joystick", f"env.xml_file=menagerie/{folder}/scene.xml",
                   f"collector.num_envs={ROWS}", "collector.physics_threads=1", "eval.every_frames=0",
                   "eval.final_episodes=0", "checkpoint.every_frames=0", "logger=none"])
    with tempfile.TemporaryDirectory() as tmp:
        env = Trainer(cfg, Path(tmp) / "run").collector.collector.env_state.rows.batch
        m0 = env.models[0]
        own = {k: getattr(m0.opt, k) for k in ("cone", "iterations", "ls_iterations")}
        print(f"{folder}: cone {m0.opt.cone}, impratio {m0.opt.impratio}, solver {m0.opt.solver}, iterations "
              f"{m0.opt.iterations}, ls {m0.opt.ls_iterations}, timestep {m0.opt.timestep}, {ROWS} rows, one thread")
        rng = np.random.default_rng(0)
        rates = {name: [] for name in VARIANTS}
        for rnd in range(ROUNDS):
            for name, opts in VARIANTS.items():
                for m in env.models:
                    for k, v in {**own, **opts}.items():
                        setattr(m.opt, k, v)
                env.reset(seed=rnd)
                spent, contacts, iters = 0.0, 0, []
                for s in range(STEPS):
                    ctrl = env.world.ctrl_of(rng.uniform(-0.5, 0.5, (ROWS, m0.nu)))
                    t0 = time.perf_counter()
                    env._physics(ctrl)  # the rows' mj_step alone: what this measures
                    spent += time.perf_counter() - t0
                    contacts += sum(d.ncon for d in env.datas)
                    iters += [d.solver_niter[0] for d in env.datas]
                    if s % 50 == 49:
                        env.reset(seed=rnd * 100 + s)
                rates[name].append(STEPS * ROWS / spent)
                print(f"round {rnd} {name}: {STEPS * ROWS / spent:,.0f} control steps/s, contacts per row "
                      f"{contacts / (STEPS * ROWS):.1f}, solver iterations {np.mean(iters):.1f}", flush=True)
        for name, r in rates.items():
            print(f"median {name}: {np.median(r):,.0f} control steps/s ({', '.join(f'{x:,.0f}' for x in r)})")


if __name__ == "__main__":
    main(*sys.argv[1:2])
