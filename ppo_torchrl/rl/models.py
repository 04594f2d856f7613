"""Actor and critic: TorchRL `ProbabilisticActor` (TanhNormal or Normal head) and `ValueOperator`.

`make_actor_critic` also returns `policy_net`, the plain module obs -> (loc, scale) inside the
actor. The fast collector steps with `NumpyPolicy`, a per-batch numpy copy of it that draws as
TorchRL's TanhNormal / Normal do; log-probabilities are then computed once per batch by the
actor's own distribution, exactly as the loss recomputes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Tuple

import numpy as np
import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.data import Bounded
from torchrl.modules import ActorValueOperator, IndependentNormal, ProbabilisticActor, TanhNormal, ValueOperator

from ppo_torchrl.envs.make import EnvSpec
from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import PRIVILEGED
from ppo_torchrl.envs.normalization import clip

ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU}
# The same activations in numpy, for NumpyPolicy.
NUMPY_ACTIVATIONS = {nn.Tanh: np.tanh, nn.ReLU: lambda x: np.maximum(x, 0),
                     nn.ELU: lambda x: np.where(x > 0, x, np.expm1(x))}
HEADS = ("tanh_normal", "normal")
STD_MODES = ("state_independent", "state_dependent")
# policy.critic_obs -> the batch key the critic's ValueOperator reads (GAE and the loss read it through its in_keys)
CRITIC_INPUTS = {"observation": "observation", "privileged": PRIVILEGED}


def _init_linear(layer: nn.Linear, gain: float, ortho: bool) -> nn.Linear:
    if ortho:
        nn.init.orthogonal_(layer.weight, gain)
        nn.init.zeros_(layer.bias)
    return layer


def mlp(in_dim: int, sizes: List[int], activation: str, ortho: bool) -> Tuple[nn.Sequential, int]:
    """Hidden layers only; returns the module and its output width."""
    layers: list[nn.Module] = []
    for size in sizes:
        layers += [_init_linear(nn.Linear(in_dim, size), math.sqrt(2), ortho), ACTIVATIONS[activation]()]
        in_dim = size
    return nn.Sequential(*layers), in_dim


class GaussianParams(nn.Module):
    """features -> (loc, scale). The std is a learned vector or a softplus of the features."""

    def __init__(self, in_dim: int, action_dim: int, cfg):
        super().__init__()
        self.loc = _init_linear(nn.Linear(in_dim, action_dim), cfg.policy_head_gain, cfg.ortho_init)
        self.state_dependent = cfg.std == "state_dependent"
        self.std_min = float(cfg.std_min)
        std_max = cfg.get("std_max") if hasattr(cfg, "get") else getattr(cfg, "std_max", None)
        self.std_cap = None if std_max is None else float(std_max) - self.std_min  # on the learned part
        if self.state_dependent:
            self.scale = _init_linear(nn.Linear(in_dim, action_dim), cfg.policy_head_gain, cfg.ortho_init)
            # softplus(bias) = exp(log_std_init) at start, like the state-independent default
            std0 = math.exp(cfg.log_std_init)
            nn.init.constant_(self.scale.bias, math.log(math.expm1(std0)))
        else:
            self.log_std = nn.Parameter(torch.full((action_dim,), float(cfg.log_std_init)))

    def forward(self, features: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        loc = self.loc(features)
        if self.state_dependent:
            scale = nn.functional.softplus(self.scale(features))
        else:
            scale = self.log_std.exp().expand_as(loc)
        if self.std_cap is not None:
            scale = scale.clamp(max=self.std_cap)
        if self.std_min > 0:
            scale = scale + self.std_min
        return loc, scale


@dataclass
class ActorCritic:
    actor: ProbabilisticActor  # reads "observation", writes "action" and "action_log_prob"
    critic: ValueOperator  # reads "observation" (policy.critic_obs=privileged: PRIVILEGED), writes "state_value"
    policy_net: nn.Module  # obs tensor -> (loc, scale), the module inside `actor`
    head: str
    action_low: torch.Tensor
    action_high: torch.Tensor

    @property
    def obs_dim(self) -> int:
        """The size of the observation the actor reads (what export traces and predict() checks)."""
        return int(self.policy_net[0][0].in_features)


def validate_policy_config(cfg) -> None:
    if cfg.head not in HEADS:
        raise ConfigError(f"policy.head='{cfg.head}' is not allowed; use one of {', '.join(HEADS)}")
    if cfg.std not in STD_MODES:
        raise ConfigError(f"policy.std='{cfg.std}' is not allowed; use one of {', '.join(STD_MODES)}")
    critic_obs = cfg.get("critic_obs", "observation")
    if critic_obs not in CRITIC_INPUTS:
        raise ConfigError(f"policy.critic_obs='{critic_obs}' is not allowed; use one of {', '.join(CRITIC_INPUTS)}")
    if critic_obs == "privileged" and cfg.shared_trunk:
        raise ConfigError("policy.critic_obs=privileged needs a critic of its own: leave out policy.shared_trunk=true "
                          "(a shared trunk reads the actor's observation)")
    if cfg.activation not in ACTIVATIONS:
        raise ConfigError(f"policy.activation='{cfg.activation}' is not allowed; use one of {', '.join(ACTIVATIONS)}")
    if not cfg.hidden_sizes or any(int(s) <= 0 for s in cfg.hidden_sizes):
        raise ConfigError(f"policy.hidden_sizes={list(cfg.hidden_sizes)} must be a non-empty list of positive widths")
    if cfg.width is not None and cfg.width <= 0:
        raise ConfigError(f"policy.width={cfg.width} must be a positive width (or null)")
    if cfg.std_min < 0:
        raise ConfigError(f"policy.std_min={cfg.std_min} must be >= 0")
    std_max = cfg.get("std_max")
    if std_max is not None and not std_max > cfg.std_min:
        raise ConfigError(f"policy.std_max={std_max} must be above policy.std_min={cfg.std_min} (or null: no cap)")


def make_actor_critic(cfg, spec: EnvSpec, device: torch.device | str = "cpu") -> ActorCritic:
    """Build the actor and critic from the `policy` config group. policy.critic_obs=privileged: the critic reads the
    env's privileged observation (spec.privileged_dim wide, batch key PRIVILEGED), the actor the observation alone."""
    validate_policy_config(cfg)
    critic_key = CRITIC_INPUTS[cfg.get("critic_obs", "observation")]
    critic_dim = spec.obs_dim if critic_key == "observation" else spec.privileged_dim
    if critic_dim is None:
        raise ConfigError("policy.critic_obs=privileged needs an env with a privileged observation (env=legged, or "
                          "env=playground's tasks with a privileged_state, e.g. env.id=Go1JoystickFlatTerrain-v1); this env has none")
    hidden = [cfg.width] * len(cfg.hidden_sizes) if cfg.width else list(cfg.hidden_sizes)
    critic_hidden = [cfg.width] * len(cfg.critic_hidden_sizes) if cfg.width else list(cfg.critic_hidden_sizes)
    low = torch.as_tensor(spec.action_low)
    high = torch.as_tensor(spec.action_high)
    action_spec = Bounded(low=low, high=high, shape=(spec.action_dim,), dtype=torch.float32)
    if cfg.head == "tanh_normal":
        dist_class, dist_kwargs = TanhNormal, {"low": low.to(device), "high": high.to(device)}
    else:
        dist_class, dist_kwargs = IndependentNormal, {}

    def probabilistic_actor(module: TensorDictModule) -> ProbabilisticActor:
        return ProbabilisticActor(
            module,
            in_keys=["loc", "scale"],
            spec=action_spec,
            distribution_class=dist_class,
            distribution_kwargs=dist_kwargs,
            return_log_prob=True,
        )

    if cfg.shared_trunk:
        trunk, width = mlp(spec.obs_dim, hidden, cfg.activation, cfg.ortho_init)
        params = GaussianParams(width, spec.action_dim, cfg)
        value_head = _init_linear(nn.Linear(width, 1), cfg.value_head_gain, cfg.ortho_init)
        avo = ActorValueOperator(
            TensorDictModule(trunk, in_keys=["observation"], out_keys=["hidden"]),
            probabilistic_actor(TensorDictModule(params, in_keys=["hidden"], out_keys=["loc", "scale"])),
            ValueOperator(value_head, in_keys=["hidden"]),
        )
        actor, critic = avo.get_policy_operator(), avo.get_value_operator()
        policy_net = nn.Sequential(trunk, params)
    else:
        body, width = mlp(spec.obs_dim, hidden, cfg.activation, cfg.ortho_init)
        policy_net = nn.Sequential(body, GaussianParams(width, spec.action_dim, cfg))
        actor = probabilistic_actor(TensorDictModule(policy_net, in_keys=["observation"], out_keys=["loc", "scale"]))
        cbody, cwidth = mlp(critic_dim, critic_hidden, cfg.activation, cfg.ortho_init)
        value_head = _init_linear(nn.Linear(cwidth, 1), cfg.value_head_gain, cfg.ortho_init)
        critic = ValueOperator(nn.Sequential(cbody, value_head), in_keys=[critic_key])
    actor.to(device)
    critic.to(device)
    return ActorCritic(actor, critic, policy_net, cfg.head, low.to(device), high.to(device))


class NumpyPolicy:
    """A numpy copy of `policy_net` that draws one action per env step.

    Stepping one env at a time, torch's per-op dispatch (a dozen ops of a few microseconds each)
    costs more than the 64-wide matmuls themselves; numpy runs the same forward in a fraction of
    that. The weights are copied with `sync()` once per batch: they only change in the update.
    The draw is TorchRL's: TanhNormal is affine(safe_tanh(loc + scale * noise)) into [low, high];
    Normal stores the raw draw (its log-prob is what the loss ratios use) and sends the env the
    draw clipped to the bounds.
    """

    def __init__(self, layers: List[nn.Module], squash: bool, low: np.ndarray, high: np.ndarray):
        self.modules = layers  # Linear, activation and GaussianParams modules, in forward order
        self.squash = squash
        self.low, self.high = low, high
        self.sync()

    @classmethod
    def from_actor(cls, actor: nn.Module) -> "NumpyPolicy":
        """From the `ProbabilisticActor` itself (what TorchRL's collectors hand a worker): its net's layers,
        its distribution (TanhNormal squashes) and its action spec's bounds."""
        layers: List[nn.Module] = []

        def walk(module: nn.Module) -> None:
            if isinstance(module, (nn.Linear, GaussianParams)) or type(module) in NUMPY_ACTIVATIONS:
                layers.append(module)
                return
            children = list(module.children())
            if not children and any(True for _ in module.parameters(recurse=False)):
                raise TypeError(f"NumpyPolicy cannot run a {type(module).__name__} layer")
            for child in children:
                walk(child)

        walk(actor)
        dist = next(m.distribution_class for m in actor.modules() if hasattr(m, "distribution_class"))
        space = actor.spec["action"].space
        return cls(layers, dist is TanhNormal, space.low.cpu().numpy(), space.high.cpu().numpy())

    def sync(self) -> None:
        """Copy the current weights of the policy net (one numpy function per layer)."""
        def linear(layer: nn.Linear):
            w, b = layer.weight.detach().cpu().numpy().T.copy(), layer.bias.detach().cpu().numpy().copy()
            return lambda x: x.dot(w) + b  # ndarray.dot: the same product as @, a little less call overhead

        self.layers = []
        for module in self.modules:
            if isinstance(module, nn.Linear):
                self.layers.append(linear(module))
            elif type(module) in NUMPY_ACTIVATIONS:
                self.layers.append(NUMPY_ACTIVATIONS[type(module)])
            else:  # GaussianParams
                self.loc_head = linear(module.loc)
                cap = np.inf if module.std_cap is None else module.std_cap
                if module.state_dependent:
                    scale_head, std_min = linear(module.scale), module.std_min
                    if module.std_cap is None:  # no cap: no np.minimum in the per-step draw
                        self.scale_head = lambda x: np.logaddexp(0, scale_head(x)) + std_min
                    else:
                        self.scale_head = lambda x: np.minimum(np.logaddexp(0, scale_head(x)), cap) + std_min
                else:  # the same std for every observation: computed once here
                    scale = np.minimum(module.log_std.detach().exp().cpu().numpy(), cap) + module.std_min
                    self.scale_head = lambda x: scale

    def loc_scale(self, obs: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        x = obs
        for layer in self.layers:
            x = layer(x)
        return self.loc_head(x), self.scale_head(x)

    def act(self, obs: np.ndarray, noise: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """(action to store, action to send to the env) for observations [n, obs_dim]."""
        loc, scale = self.loc_scale(obs)
        base = (loc + scale * noise).astype(np.float32, copy=False)
        action = to_bounds(base, self.low, self.high, self.squash)
        return (action, action) if self.squash else (base, action)


class SamplingPolicy(nn.Module):
    """What TorchRL's Collector steps with: "observation" -> "action", drawn as the actor's distribution draws
    (TanhNormal: the squashed sample; Normal: the raw sample, which ClipActionToBounds clips for the env), with
    plain tensor ops over the actor's own net. It builds no distribution object and no log-probability per
    step (the trainer computes log-probabilities once per batch, as for the fast collector)."""

    def __init__(self, ac: ActorCritic):
        super().__init__()
        self.policy_net = ac.policy_net
        self.register_buffer("low", ac.action_low.clone())
        self.register_buffer("high", ac.action_high.clone())
        self.squash = ac.head == "tanh_normal"

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        loc, scale = self.policy_net(observation)
        base = loc + scale * torch.randn_like(loc)
        return to_bounds(base, self.low, self.high, True) if self.squash else base


def sampling_policy(ac: ActorCritic) -> TensorDictModule:
    return TensorDictModule(SamplingPolicy(ac), in_keys=["observation"], out_keys=["action"])


def to_bounds(loc, low, high, squash: bool):
    """The one map from a draw or the mean to an action in [low, high], for torch tensors and numpy arrays alike:
    TanhNormal's squash or the Normal head's clip. `evaluate`, an exported policy.pt, the lean draw of TorchRL's
    Collector and the fast collector's numpy draw all take it. The squash is the forward pass of TorchRL's
    `safetanh_noeps` (tanh clamped 1 - resolution inside the bounds) as plain ops, which TorchScript can export
    (its autograd.Function cannot); tests/test_models.py checks it against TorchRL's TanhNormal."""
    tensor = isinstance(loc, torch.Tensor)
    if squash:
        limit = 1.0 - (torch.finfo(loc.dtype) if tensor else np.finfo(loc.dtype)).resolution
        return (high + low) / 2 + (high - low) / 2 * clip(loc.tanh() if tensor else np.tanh(loc), limit)
    return torch.maximum(torch.minimum(loc, high), low) if tensor else np.minimum(np.maximum(loc, low), high)


def deterministic_action(ac: ActorCritic, loc: torch.Tensor) -> torch.Tensor:
    """The action a deterministic evaluation takes: the mean, squashed or clipped to the bounds."""
    return to_bounds(loc, ac.action_low, ac.action_high, ac.head == "tanh_normal")


class _DeterministicHead(nn.Module):
    def __init__(self, ac: ActorCritic):
        super().__init__()
        self.policy_net, self.ac = ac.policy_net, ac

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return deterministic_action(self.ac, self.policy_net(observation)[0])


def deterministic_policy(ac: ActorCritic) -> TensorDictModule:
    """The actor in DETERMINISTIC mode as a plain TensorDictModule: "observation" -> "action", the same
    values as `ac.actor` under `set_exploration_type(DETERMINISTIC)` (tests/test_models.py), without
    building a distribution and its log-prob each step (~27% of an eval step on Hopper)."""
    return TensorDictModule(_DeterministicHead(ac), in_keys=["observation"], out_keys=["action"])
