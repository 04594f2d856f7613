"""One minibatch step of the update: loss -> backward -> grad-norm clip -> optimizer step.

Two implementations of the same math behind one call, `step(minibatch) -> (metrics, grad_norm)`, at
the learning rate the trainer set in the optimizer's param group:

- `EagerStep` (compile=false, and losses torch.compile cannot take): the TorchRL loss module,
  `loss.backward()`, `clip_grad_norm_` and `torch.optim.Adam(W).step()`, each a separate call.
- `FusedStep` (compile=auto on long runs, compile=true): the whole step as ONE compiled function,
  in the spirit of LeanRL: `torch.func.grad_and_value` over a functional call of the same TorchRL
  loss module, the same global-norm clip (`clip_grad_norm_`'s formula) and the same Adam / AdamW
  update (`torch.optim`'s formula), written on the optimizer's own state tensors (`exp_avg`,
  `exp_avg_sq`, `step`), so checkpoints, resumes and `init_from_optimizer` are one format for both.
  One compiled call per minibatch instead of four Python-level phases: ~2x faster on Hopper's
  64-64 networks (benchmarks/README.md).

Both check the loss and the gradient norm before a step is taken: a non-finite one leaves the
weights and the optimizer state as they were, and `metrics[0]` (the loss) or `grad_norm` says which.
"""

from __future__ import annotations

import math
from typing import List, Optional, Tuple

import torch
from tensordict import TensorDictBase
from torch.func import grad_and_value

from torchrl.objectives import LossModule

from ppo_torchrl.rl.losses import LOSS_METRICS, make_loss_step

StepResult = Tuple[torch.Tensor, torch.Tensor]  # (loss and LOSS_METRICS values, stacked; grad norm)


class EagerStep:
    """loss module -> backward -> clip_grad_norm_ -> optimizer.step(), eagerly (or with the loss compiled)."""

    def __init__(self, loss_module: LossModule, optimizer: torch.optim.Optimizer, params: List[torch.Tensor],
                 normalize_advantage: bool, max_grad_norm: Optional[float]):
        self.loss_step = make_loss_step(loss_module, normalize_advantage)
        self.optimizer, self.params = optimizer, params
        self.max_norm = max_grad_norm or math.inf  # with None the norm is only measured
        self.metric_keys: Optional[List[str]] = None  # the LOSS_METRICS the loss module outputs

    def __call__(self, minibatch: TensorDictBase) -> StepResult:
        loss, out = self.loss_step(minibatch)
        if self.metric_keys is None:
            self.metric_keys = [k for k in out.keys() if k in LOSS_METRICS]
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(self.params, self.max_norm)
        metrics = torch.stack([loss.detach(), *(out.get(k).detach().float().mean() for k in self.metric_keys)])
        if torch.isfinite(metrics[0] + grad_norm):  # no step from a non-finite loss or gradient
            self.optimizer.step()
        return metrics, grad_norm


class FusedStep:
    """The same step as EagerStep, as one function that torch.compile takes whole."""

    def __init__(self, loss_module: LossModule, optimizer: torch.optim.Optimizer, params: List[torch.Tensor],
                 normalize_advantage: bool, max_grad_norm: Optional[float], compile: bool = True):
        if len(optimizer.param_groups) != 1 or type(optimizer) not in (torch.optim.Adam, torch.optim.AdamW):
            raise ValueError("FusedStep implements one param group of Adam or AdamW")
        group = optimizer.param_groups[0]
        if group["amsgrad"] or group["maximize"]:
            raise ValueError("FusedStep does not implement amsgrad or maximize")
        self.optimizer = optimizer
        self.loss_step = make_loss_step(loss_module, normalize_advantage)
        by_id = {id(p): name for name, p in loss_module.named_parameters()}
        self.names = [by_id[id(p)] for p in params]
        self.params = params
        self.max_norm = max_grad_norm or math.inf
        self.betas, self.eps, self.weight_decay = group["betas"], group["eps"], group["weight_decay"]
        self.decoupled = isinstance(optimizer, torch.optim.AdamW)
        self.lr = torch.zeros((), device=params[0].device)  # a tensor: a new lr is no recompile
        self.metric_keys: Optional[List[str]] = None
        # gradients with respect to the weights (loss_step's 2nd argument); the module's output rides as aux
        self._grad_and_loss = grad_and_value(self.loss_step, argnums=1, has_aux=True)
        # Guards on tensors only (their shapes, dtypes, strides): everything else the step reads (the
        # loss module's settings, the clip, Adam's betas and eps) is fixed for the life of this object,
        # and what changes between calls (weights, optimizer state, lr, minibatch) is a tensor. Dynamo's
        # full guard set cost ~0.1 ms of a ~0.3 ms call (about a quarter of the update), and one of its
        # guards, on the size of tensordict's pytree constructor table, failed after the first call
        # and compiled the step a second time (~2.5 s of every run's start).
        # Inductor's C++ wrapper calls the kernels from C++ instead of generated Python, and the size
        # and alignment asserts on the inputs are dropped (the guards above already check them): the
        # update went from ~103 to ~85 ms per 2048-frame batch (benchmarks/README.md).
        options = {"guard_filter_fn": torch.compiler.keep_tensor_guards_unsafe,
                   "cpp_wrapper": True, "size_asserts": False, "alignment_asserts": False}
        self._step = torch.compile(self._fused, options=options) if compile else self._fused

    def _state(self) -> List[Tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
        """(step, exp_avg, exp_avg_sq) per parameter, in torch.optim's own state (created as Adam does)."""
        state = self.optimizer.state
        for p in self.params:
            if not state[p]:
                state[p] = {"step": torch.tensor(0.0, dtype=torch.float32, device=p.device),
                            "exp_avg": torch.zeros_like(p, memory_format=torch.preserve_format),
                            "exp_avg_sq": torch.zeros_like(p, memory_format=torch.preserve_format)}
        return [(state[p]["step"], state[p]["exp_avg"], state[p]["exp_avg_sq"]) for p in self.params]

    def _fused(self, minibatch: TensorDictBase, lr: torch.Tensor, state: list) -> StepResult:
        weights = {name: p.detach() for name, p in zip(self.names, self.params)}
        grads, (loss, out) = self._grad_and_loss(minibatch, weights)
        metrics = torch.stack([loss, *(out.get(k).detach().float().mean() for k in self.metric_keys)])
        grads = [grads[name] for name in self.names]
        # clip_grad_norm_: the 2-norm of all gradients together, scaled down to max_norm
        grad_norm = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g) for g in grads]))
        ok = torch.isfinite(loss) & torch.isfinite(grad_norm)
        coef = torch.clamp(self.max_norm / (grad_norm + 1e-6), max=1.0)
        beta1, beta2 = self.betas
        with torch.no_grad():
            for p, g, (step, exp_avg, exp_avg_sq) in zip(self.params, grads, state):
                # torch.optim.Adam / AdamW (amsgrad off), one parameter
                g = g * coef
                if self.weight_decay and not self.decoupled:
                    g = g + self.weight_decay * p
                new_step = step + 1
                new_avg = torch.lerp(exp_avg, g, 1 - beta1)
                new_avg_sq = exp_avg_sq * beta2 + (1 - beta2) * g * g
                denom = new_avg_sq.sqrt() / torch.sqrt(1 - beta2 ** new_step) + self.eps
                new_p = p * (1 - lr * self.weight_decay) if self.weight_decay and self.decoupled else p
                new_p = new_p - (lr / (1 - beta1 ** new_step)) * new_avg / denom
                p.copy_(torch.where(ok, new_p, p))
                exp_avg.copy_(torch.where(ok, new_avg, exp_avg))
                exp_avg_sq.copy_(torch.where(ok, new_avg_sq, exp_avg_sq))
                step.copy_(torch.where(ok, new_step, step))
        return metrics, grad_norm

    def __call__(self, minibatch: TensorDictBase) -> StepResult:
        if self.metric_keys is None:  # once: which LOSS_METRICS this loss module outputs
            with torch.no_grad(), torch.random.fork_rng(devices=[]):  # leaves the RNG stream as it was
                _, out = self.loss_step(minibatch.clone())
            self.metric_keys = [k for k in out.keys() if k in LOSS_METRICS]
        self.lr.fill_(self.optimizer.param_groups[0]["lr"])
        return self._step(minibatch, self.lr, self._state())



def make_minibatch_step(cfg, loss_module: LossModule, optimizer: torch.optim.Optimizer, params: List[torch.Tensor],
                        compile: bool):
    """FusedStep, compiled, when `compile` is on (trainer.use_compile); EagerStep otherwise."""
    kind = FusedStep if compile else EagerStep
    extra = {"compile": True} if compile else {}
    return kind(loss_module, optimizer, params, cfg.loss.normalize_advantage, cfg.optim.max_grad_norm, **extra)
