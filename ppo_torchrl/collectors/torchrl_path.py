"""TorchRL's own `Collector` over the env's TorchRL transforms (collector.backend=torchrl, or auto with
env.transforms.extra), made to resume where it runs, in this process or in a worker of TorchRL's
multi-process and Ray collectors. Its state is TorchRL's (the env's transforms', EnvState's snapshot with
each env's position among them) plus its own entry (internals.OWN): the torch RNG of the process it runs in,
which its policy samples with (a worker's is nobody else's to save). Loading a saved state sets that RNG and
resets the collector, whose reset restores each env's saved position and gives back the observation its
policy was to act on (`EnvState.continue_episodes`); a state pushed between batches (no own entry) loads
the statistics alone. The start line calls it torchrl.Collector: it steps exactly as TorchRL's does.
"""

from __future__ import annotations

import torch
from torchrl.collectors import Collector

from ppo_torchrl.envs.state import env_state_of
from ppo_torchrl.internals import OWN


class TorchRLCollector(Collector):
    def state_dict(self):
        state = super().state_dict()
        # bytes, not a tensor: a worker's state comes back every batch (the statistics' merge), and a tensor would
        # travel through shared memory (env_state.pack says what that costs); its RNG only matters on resume
        state[OWN] = {"torch_rng": torch.get_rng_state().numpy().tobytes()}
        return state

    def load_state_dict(self, state_dict, **kwargs) -> None:
        state = dict(state_dict)
        own = state.pop(OWN, None)
        super().load_state_dict(state, **kwargs)
        if own is not None:
            if env_state_of(self.env).continue_episodes(now=False):
                self.reset()  # each env back where it was (its reset takes the held position)
            torch.set_rng_state(torch.frombuffer(bytearray(own["torch_rng"]), dtype=torch.uint8))
