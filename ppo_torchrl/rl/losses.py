"""Loss modules by name: `loss=clip_ppo|kl_ppo|ppo|a2c|reinforce` picks a TorchRL LossModule.

Every loss reads the same batch keys (observation, action, action_log_prob, advantage,
value_target) and returns terms named `loss_*`; the trainer sums those terms, so adding a loss
is one entry in LOSSES.
"""

from __future__ import annotations

from typing import Callable, Dict, Optional, Tuple

import torch
from tensordict import TensorDictBase
from torch.func import functional_call

from torchrl.objectives import A2CLoss, ClipPPOLoss, KLPENPPOLoss, LossModule, PPOLoss, ReinforceLoss

from ppo_torchrl.envs.layout import PRIVILEGED
from ppo_torchrl.rl.models import ActorCritic


def _ppo_kwargs(cfg) -> dict:
    return dict(
        entropy_bonus=cfg.entropy_coef > 0,
        entropy_coeff=cfg.entropy_coef,
        samples_mc_entropy=cfg.entropy_samples,
        critic_coeff=cfg.critic_coef,
        loss_critic_type=cfg.critic_loss,
        normalize_advantage=False,  # loss_step normalizes per minibatch, the same for every loss
        clip_value=cfg.clip_value,
        functional=False,  # use the modules' own parameters: no per-call parameter re-wrapping
    )


def _clip_ppo(cfg, ac: ActorCritic) -> LossModule:
    return ClipPPOLoss(ac.actor, ac.critic, clip_epsilon=cfg.clip_epsilon, **_ppo_kwargs(cfg))


def _kl_ppo(cfg, ac: ActorCritic) -> LossModule:
    return KLPENPPOLoss(ac.actor, ac.critic, dtarg=cfg.kl_target, beta=cfg.kl_beta, **_ppo_kwargs(cfg))


def _ppo(cfg, ac: ActorCritic) -> LossModule:
    return PPOLoss(ac.actor, ac.critic, **_ppo_kwargs(cfg))


def _a2c(cfg, ac: ActorCritic) -> LossModule:
    return A2CLoss(
        ac.actor,
        ac.critic,
        entropy_bonus=cfg.entropy_coef > 0,
        entropy_coeff=cfg.entropy_coef,
        samples_mc_entropy=cfg.entropy_samples,
        critic_coeff=cfg.critic_coef,
        loss_critic_type=cfg.critic_loss,
        clip_value=cfg.clip_value,
        functional=False,
    )


def _reinforce(cfg, ac: ActorCritic) -> LossModule:
    # REINFORCE with the critic as a baseline; the advantage comes from the trainer's estimator.
    return ReinforceLoss(ac.actor, ac.critic, loss_critic_type=cfg.critic_loss, clip_value=cfg.clip_value,
                         functional=False)


LOSSES: Dict[str, Callable[[object, ActorCritic], LossModule]] = {
    "clip_ppo": _clip_ppo,
    "kl_ppo": _kl_ppo,
    "ppo": _ppo,
    "a2c": _a2c,
    "reinforce": _reinforce,
}

# Losses torch.compile cannot take whole: KLPENPPOLoss updates its KL coefficient in place inside
# forward, which inductor refuses. compile=auto leaves these eager.
NOT_COMPILABLE = {"kl_ppo": "its adaptive KL coefficient is updated in place inside the loss"}
KL_LOSSES = ("clip_ppo", "kl_ppo", "ppo")  # the losses that output their approximate KL (loss.stop_kl reads it)


# The batch keys the losses read (KLPENPPOLoss also reads the old loc/scale; value clipping the old
# state_value; an asymmetric critic its privileged observation): the update indexes only these per minibatch.
LOSS_INPUT_KEYS = ("observation", "action", "action_log_prob", "advantage", "value_target", "state_value",
                   "loc", "scale", PRIVILEGED)
# TorchRL loss output key -> the metric name in metrics.csv
LOSS_METRICS = {
    "loss_objective": "loss/objective", "loss_actor": "loss/objective",
    "loss_critic": "loss/critic", "loss_value": "loss/critic",
    "loss_entropy": "loss/entropy",
    "kl_approx": "train/approx_kl", "kl": "train/approx_kl", "clip_fraction": "train/clipfrac",
}
OPTIMIZERS = {"adam": torch.optim.Adam, "adamw": torch.optim.AdamW}


def make_loss(cfg, ac: ActorCritic) -> LossModule:
    return LOSSES[cfg.name](cfg, ac)


def make_optimizer(cfg, params, device: torch.device) -> torch.optim.Optimizer:
    """The `optim` group: Adam or AdamW (fused on CPU) over the loss module's trainable parameters."""
    return OPTIMIZERS[cfg.name](params, lr=cfg.lr, eps=cfg.eps, weight_decay=cfg.weight_decay,
                                **({"fused": True} if device.type == "cpu" else {}))


def make_loss_step(loss_module: LossModule, normalize_advantage: bool) -> Callable:
    """minibatch -> (summed loss, the loss module's output).

    Advantages are normalized per minibatch here, the same for every loss (the modules' own
    option is off), as CleanRL and SB3 do. With `weights` ({name: tensor} of the module's
    parameters) the module runs on those instead of its own (torch.func.functional_call), which is
    how minibatch.FusedStep takes its gradients.
    """

    def loss_step(minibatch: TensorDictBase, weights: Optional[dict] = None) -> Tuple[torch.Tensor, TensorDictBase]:
        if normalize_advantage:
            adv = minibatch.get("advantage")
            minibatch.set("advantage", (adv - adv.mean()) / (adv.std() + 1e-8))
        out = loss_module(minibatch) if weights is None else \
            functional_call(loss_module, weights, (minibatch,), tie_weights=False)
        return sum(v for k, v in out.items() if k.startswith("loss_")), out

    return loss_step
