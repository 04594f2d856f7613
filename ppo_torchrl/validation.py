"""Every value checked before anything runs or is written: the entry point's Lifecycle calls `validate_config`
on the composed config before Hydra starts the job, and hands the env it built to the trainer (a Trainer
built without one, by a test or a library user, checks its config itself). The schema (config.py) already
checks keys and types; this checks ranges, choices against each component's registry, and the env itself
(a missing dependency or a bad model file fails here and not after hours of training).
"""

from __future__ import annotations

import importlib.util

from omegaconf import OmegaConf

from ppo_torchrl.errors import ConfigError

SEED_LIMIT = 2**32  # numpy's and gymnasium's seeds are 32-bit
MAX_TOTAL_FRAMES = 10**12  # a trillion frames is years on any machine: a larger budget is a typo
COMPILE_CHOICES = ("auto", "true", "false")
CRITIC_LOSSES = ("l2", "l1", "smooth_l1")
DISTRIBUTED = ("ray",)
RAY_INSTALL = 'pip install -e ".[ray]" (or: pip install "ray[default]<3")'


def one_of(name: str, value, choices) -> tuple:
    return value in choices, f"{name}='{value}' is not known; use one of {', '.join(choices)}"


def validate_config(cfg, keep_env: bool = False, build_env: bool = True):
    """Raise ConfigError naming the first bad value; return the env's spec (shapes and bounds), built from the
    env itself; keep_env: with the env it built still open (`EnvSpec.env`, a training env's first). build_env=False:
    the values only, for a sweep's job whose env config an earlier job's check built (returns None)."""
    from ppo_torchrl.rl.advantage import ESTIMATORS
    from ppo_torchrl.collectors import CHOICES, resolve_backend
    from ppo_torchrl.config_data import transform_entry
    from ppo_torchrl.envs.make import env_spec
    from ppo_torchrl.run.eval_worker import BACKGROUND_CHOICES
    from ppo_torchrl.run.loggers import LOGGERS
    from ppo_torchrl.rl.losses import KL_LOSSES, LOSSES, OPTIMIZERS, NOT_COMPILABLE
    from ppo_torchrl.rl.models import validate_policy_config
    from ppo_torchrl.envs.normalization import transforms_checks

    missing = sorted(OmegaConf.missing_keys(cfg))
    if missing:
        example = " (any registered Gymnasium id: env=gym env.id=Swimmer-v4)" if "env.id" in missing else ""
        raise ConfigError(f"{', '.join(missing)} must be given{example}")
    check_keys_against_schema(cfg)
    check_finite(cfg)
    for i, entry in enumerate(cfg.env.transforms.extra or []):  # what it names, before any env is built
        transform_entry(entry, f"env.transforms.extra[{i}]")
    c, loss, t, adv, env = cfg.collector, cfg.loss, cfg.env.transforms, cfg.advantage, cfg.env
    compile_choice = str(cfg.compile).lower()
    positive_or_null = lambda v: v is None or v > 0  # noqa: E731
    checks = [
        (0 <= cfg.seed < SEED_LIMIT, f"seed={cfg.seed} must be in [0, 2^32)"),
        (all(0 <= s < SEED_LIMIT for s in cfg.trial_seeds) and len(set(cfg.trial_seeds)) == len(cfg.trial_seeds),
         f"trial_seeds={list(cfg.trial_seeds)} must be distinct seeds in [0, 2^32), e.g. [6,7,8]"),
        (not (cfg.trial_seeds and cfg.resume), "resume= continues one seed's run: give it <run dir>/seed<k> "
                                               "and leave trial_seeds out"),
        (cfg.trial_prune_below is None or cfg.trial_seeds,
         f"trial_prune_below={cfg.trial_prune_below} stops a trial of several seeds: give trial_seeds=[6,7,8] too"),
        (c.num_envs >= 1, f"collector.num_envs={c.num_envs} must be >= 1"),
        (c.frames_per_batch >= 1, f"collector.frames_per_batch={c.frames_per_batch} must be >= 1"),
        (c.num_envs < 1 or c.frames_per_batch % c.num_envs == 0,
         f"collector.frames_per_batch={c.frames_per_batch} must be divisible by collector.num_envs={c.num_envs}"),
        (c.workers >= 1, f"collector.workers={c.workers} must be >= 1"),
        (c.workers < 1 or c.num_envs < 1 or c.frames_per_batch % (c.workers * c.num_envs) == 0,
         f"collector.frames_per_batch={c.frames_per_batch} must be divisible by collector.workers x "
         f"collector.num_envs={c.workers} x {c.num_envs}: each worker steps an equal share"),
        (c.distributed is None or c.distributed in DISTRIBUTED,
         f"collector.distributed='{c.distributed}' is not known; use null (local processes) or "
         f"{', '.join(DISTRIBUTED)}"),
        (c.ray_address is None or c.distributed == "ray",
         f"collector.ray_address={c.ray_address} needs collector.distributed=ray"),
        (c.total_frames >= c.frames_per_batch,
         f"collector.total_frames={c.total_frames} must be >= collector.frames_per_batch={c.frames_per_batch}"),
        (c.total_frames <= MAX_TOTAL_FRAMES, f"collector.total_frames={c.total_frames} must be <= 10^12"),
        one_of("collector.backend", c.backend, CHOICES),
        one_of("compile", compile_choice, COMPILE_CHOICES),
        one_of("eval.background", str(cfg.eval.background).lower(), BACKGROUND_CHOICES),
        (not (compile_choice == "true" and loss.name in NOT_COMPILABLE),
         f"compile=true does not work with loss={loss.name}: {NOT_COMPILABLE.get(loss.name)}; use compile=auto or false"),
        one_of("optim.name", cfg.optim.name, OPTIMIZERS),
        (cfg.optim.lr > 0, f"optim.lr={cfg.optim.lr} must be > 0"),
        (cfg.optim.eps > 0, f"optim.eps={cfg.optim.eps} must be > 0"),
        (cfg.optim.weight_decay >= 0, f"optim.weight_decay={cfg.optim.weight_decay} must be >= 0"),
        (positive_or_null(cfg.optim.max_grad_norm),
         f"optim.max_grad_norm={cfg.optim.max_grad_norm} must be > 0 (or null to disable)"),
        one_of("loss.name", loss.name, LOSSES),
        (loss.epochs >= 1, f"loss.epochs={loss.epochs} must be >= 1"),
        (positive_or_null(loss.minibatch_size), f"loss.minibatch_size={loss.minibatch_size} must be >= 1"),
        (not loss.minibatch_size or c.frames_per_batch % loss.minibatch_size == 0,
         f"collector.frames_per_batch={c.frames_per_batch} is not divisible into minibatches of "
         f"loss.minibatch_size={loss.minibatch_size}"),
        (0 < loss.clip_epsilon < 1, f"loss.clip_epsilon={loss.clip_epsilon} must be in (0, 1): the ratio is "
                                    "clipped to [1 - eps, 1 + eps]"),
        (loss.entropy_coef >= 0 and loss.critic_coef >= 0,
         f"loss.entropy_coef={loss.entropy_coef} and loss.critic_coef={loss.critic_coef} must be >= 0"),
        one_of("loss.critic_loss", loss.critic_loss, CRITIC_LOSSES),
        (positive_or_null(loss.clip_value), f"loss.clip_value={loss.clip_value} must be > 0 (or null)"),
        (loss.kl_target > 0 and loss.kl_beta >= 0, f"loss.kl_target={loss.kl_target} must be > 0 and loss.kl_beta >= 0"),
        (loss.entropy_samples >= 1, f"loss.entropy_samples={loss.entropy_samples} must be >= 1"),
        (positive_or_null(loss.stop_kl), f"loss.stop_kl={loss.stop_kl} must be > 0 (or null: every epoch)"),
        (loss.stop_kl is None or loss.name in KL_LOSSES,
         f"loss.stop_kl needs a loss that measures its KL ({', '.join(KL_LOSSES)}), not loss={loss.name}"),
        (not adv.recompute or adv.name == "gae",
         f"advantage.recompute=true recomputes GAE with the updated critic; advantage={adv.name} has no critic in it"),
        one_of("advantage.name", adv.name, ESTIMATORS),
        (0 <= adv.gamma <= 1 and 0 <= adv.lmbda <= 1,
         f"advantage.gamma={adv.gamma} and advantage.lmbda={adv.lmbda} must lie in [0, 1]"),
        *transforms_checks(t),  # beside the normalization they configure (normalization.py)
        (positive_or_null(env.max_episode_steps),
         f"env.max_episode_steps={env.max_episode_steps} must be > 0 (or null: the env's own limit)"),
        (env.locomotion.frame_skip >= 1, f"env.locomotion.frame_skip={env.locomotion.frame_skip} must be >= 1"),
        (cfg.eval.every_frames >= 0 and cfg.eval.episodes >= 1 and cfg.eval.final_episodes >= 0,
         "eval.every_frames and eval.final_episodes must be >= 0 and eval.episodes >= 1"),
        (len(cfg.eval.video_episodes) >= 1 and all(0 <= e < cfg.eval.episodes for e in cfg.eval.video_episodes),
         f"eval.video_episodes={list(cfg.eval.video_episodes)} must name episodes in 0..{cfg.eval.episodes - 1} "
         f"(eval.episodes={cfg.eval.episodes}), e.g. [0] or [0,3]"),
        (positive_or_null(cfg.eval.video_length),
         f"eval.video_length={cfg.eval.video_length} must be > 0 seconds (or null: whole episodes)"),
        (cfg.checkpoint.every_frames >= 0 and cfg.checkpoint.keep_last >= 0,
         "checkpoint.every_frames and checkpoint.keep_last must be >= 0"),
        one_of("logger", cfg.logger.name, LOGGERS),
        (cfg.torch_threads >= 1, f"torch_threads={cfg.torch_threads} must be >= 1"),
    ]
    for ok, message in checks:
        if not ok:
            raise ConfigError(message)
    from ppo_torchrl.envs.values import check_env

    check_env(env)  # after the plain values: env=legged reads its model here
    if env.get("xml_file"):
        from ppo_torchrl.tasks.locomotion.world import heading_angle

        heading_angle(env.locomotion.heading)
    resolve_device(cfg.device)
    resolve_backend(cfg)
    if c.workers > 1 and not c.distributed:
        check_open_files(c.workers)
    if c.distributed == "ray" and importlib.util.find_spec("ray") is None:
        raise ConfigError(f"collector.distributed=ray needs Ray, which is not installed: {RAY_INSTALL}")
    validate_policy_config(cfg.policy)
    if not build_env:
        return None
    spec = env_spec(cfg.env, keep_env=keep_env)
    if cfg.policy.critic_obs == "privileged" and spec.privileged_dim is None:
        spec.close()
        raise ConfigError(f"policy.critic_obs=privileged needs an env with a privileged observation (env=legged, or "
                          f"env=playground's tasks with a privileged_state, e.g. env.id=Go1JoystickFlatTerrain-v1); env.id={cfg.env.id} "
                          "has none")
    return spec



def check_open_files(workers: int) -> None:
    """Worker processes hold open files: measured on Hopper, the main process peaked at 64 with 2 workers and 101
    with 4 (each worker at 45 and 67). Below that, a worker failed to start, as a traceback from each queue and an
    internal error after a minute (`ulimit -n 48`). A soft limit below the need is raised toward the hard one (a
    process may); a hard limit below it is one line before anything starts."""
    import resource

    from ppo_torchrl.errors import EnvironmentFault

    need = 64 + 32 * workers  # the measured peak with half again as much to spare
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= need:
        return
    if hard != resource.RLIM_INFINITY and hard < need:
        raise EnvironmentFault(f"collector.workers={workers} needs about {need} open files and this shell allows "
                               f"{hard} (ulimit -n); raise it (ulimit -n 4096) or use fewer collector.workers")
    resource.setrlimit(resource.RLIMIT_NOFILE, (need if hard == resource.RLIM_INFINITY else min(hard, 4 * need), hard))


def check_finite(cfg) -> None:
    """NaN nowhere; infinity only in a range or in the env's own make_kwargs (`optim.lr=inf` stopped at the
    first update before)."""
    from ppo_torchrl.envs.values import finite

    data = OmegaConf.to_container(cfg, resolve=True)
    data.pop("hydra", None)
    finite(data, "")


def resolve_device(name: str):
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name not in ("cpu", "cuda") and not name.startswith("cuda:"):
        raise ConfigError(f"device='{name}' is not allowed; use cpu, cuda or auto")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise ConfigError(f"device='{name}' was asked for but no CUDA device is available; use device=cpu or device=auto")
    return torch.device(name)


def check_keys_against_schema(cfg) -> None:
    """`+group.key=v` can add a key the schema lacks; such a key would be silently ignored."""
    from ppo_torchrl.config import Config

    schema = OmegaConf.structured(Config)
    data = OmegaConf.to_container(cfg, resolve=False)
    data.pop("hydra", None)
    try:
        OmegaConf.merge(schema, data)
    except Exception as exc:  # omegaconf's key/validation errors carry the full key
        key = getattr(exc, "full_key", None) or ""
        raise ConfigError(f"unknown or invalid config key '{key}': {str(exc).splitlines()[0]}") from exc
