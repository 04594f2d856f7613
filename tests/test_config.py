import pytest
from omegaconf.errors import ConfigAttributeError, ConfigKeyError, ValidationError
from hydra.errors import ConfigCompositionException

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.validation import validate_config

from conftest import compose_config


def test_defaults_reproduce_the_cleanrl_mujoco_settings():
    cfg = compose_config(["env=Walker2d-v5"])  # an env file without tuned values
    assert cfg.env.id == "Walker2d-v5"
    assert (cfg.collector.frames_per_batch, cfg.collector.total_frames, cfg.collector.num_envs) == (2048, 1_000_000, 1)
    assert (cfg.loss.name, cfg.loss.epochs, cfg.loss.minibatch_size) == ("clip_ppo", 10, 64)
    assert cfg.collector.frames_per_batch // cfg.loss.minibatch_size == 32
    assert (cfg.loss.clip_epsilon, cfg.loss.entropy_coef, cfg.loss.critic_coef) == (0.2, 0.0, 0.5)
    assert (cfg.advantage.gamma, cfg.advantage.lmbda) == (0.99, 0.95)
    assert (cfg.optim.lr, cfg.optim.eps, cfg.optim.max_grad_norm, cfg.optim.anneal_lr) == (3e-4, 1e-5, 0.5, True)
    assert list(cfg.policy.hidden_sizes) == [64, 64] and cfg.policy.activation == "tanh"
    assert (cfg.policy.width, cfg.policy.log_std_init, cfg.policy.ortho_init) == (None, 0.0, True)
    assert (cfg.policy.policy_head_gain, cfg.policy.value_head_gain) == (0.01, 1.0)
    assert (cfg.env.transforms.obs_norm, cfg.env.transforms.reward_norm) == ("running", "return")
    assert (cfg.env.transforms.obs_clip, cfg.env.transforms.reward_clip) == (10.0, 10.0)
    validate_config(cfg)


@pytest.mark.parametrize("env", ["Hopper", "HalfCheetah", "Walker2d", "Ant", "Humanoid", "InvertedPendulum"])
@pytest.mark.parametrize("version", ["v4", "v5"])
def test_every_env_file_composes(env, version):
    assert compose_config([f"env={env}-{version}"]).env.id == f"{env}-{version}"


def test_env_files_carry_their_tuned_values():
    hopper = compose_config(["env=Hopper-v4"])
    assert (hopper.advantage.gamma, hopper.policy.width, hopper.loss.clip_epsilon, hopper.optim.lr) == (0.995, 128, 0.1, 2e-4)
    cheetah = compose_config(["env=HalfCheetah-v4"])
    assert (cheetah.policy.log_std_init, cheetah.policy.width, cheetah.policy.activation) == (-2.0, 256, "relu")
    assert (cheetah.collector.frames_per_batch, cheetah.loss.epochs, cheetah.optim.anneal_lr) == (512, 20, False)
    for env, log_std, gamma in (("Ant-v4", -0.7, 0.99), ("Humanoid-v4", -1.0, 0.99), ("Walker2d-v4", 0.0, 0.995)):
        cfg = compose_config([f"env={env}"])  # 8 envs x 256 steps, value loss 0.25
        assert (cfg.collector.num_envs, cfg.collector.frames_per_batch, cfg.loss.critic_coef) == (8, 2048, 0.25)
        assert (cfg.policy.log_std_init, cfg.optim.lr, cfg.advantage.gamma) == (log_std, 3e-4, gamma)
        validate_config(cfg)


# (frames_per_batch, epochs, minibatch_size, lr, anneal_lr, clip, entropy_coef) of each source document
PRESET_LOOP_VALUES = {
    "arena_hopper": (2048, 10, 64, 3e-4, True, 0.2, 0.0),
    "practical_rl_halfcheetah": (2048, 10, 64, 3e-4, True, 0.2, 0.0),
    "aidl_halfcheetah": (640, 45, 128, 1e-4, False, 0.1, 0.01),
}


@pytest.mark.parametrize("preset", sorted(PRESET_LOOP_VALUES))
def test_presets_keep_their_own_values_over_tuned_env_files(preset):
    cfg = compose_config([f"experiment={preset}"])
    assert (cfg.policy.width, cfg.policy.activation, cfg.policy.ortho_init, cfg.policy.log_std_init) == (None, "tanh", True, 0.0)
    assert (cfg.advantage.gamma, cfg.advantage.lmbda) == (0.99, 0.95)
    assert (cfg.collector.frames_per_batch, cfg.loss.epochs, cfg.loss.minibatch_size, cfg.optim.lr, cfg.optim.anneal_lr,
            cfg.loss.clip_epsilon, cfg.loss.entropy_coef) == PRESET_LOOP_VALUES[preset]


def test_group_swaps_by_name():
    cfg = compose_config(["loss=kl_ppo", "policy=tanh_normal", "optim.lr=1e-3", "seed=7"])
    assert (cfg.loss.name, cfg.policy.head, cfg.optim.lr, cfg.seed) == ("kl_ppo", "tanh_normal", 1e-3, 7)
    a2c = compose_config(["loss=a2c"])
    assert a2c.loss.epochs == 1 and a2c.loss.minibatch_size is None


def test_generic_env_takes_any_id():
    assert compose_config(["env=gym", "env.id=Swimmer-v4"]).env.id == "Swimmer-v4"


@pytest.mark.parametrize(
    "override",
    ["seed=notanint", "collector.frames_per_batch=abc", "optim.lr=fast", "loss.epochs=1.5"],
)
def test_wrong_type_fails_at_compose(override):
    with pytest.raises((ConfigCompositionException, ValidationError)):
        compose_config([override])


@pytest.mark.parametrize("override", ["loss.clip_eps=0.1", "collector.frames=10"])
def test_unknown_key_fails_at_compose(override):
    with pytest.raises((ConfigCompositionException, ConfigAttributeError, ConfigKeyError)):
        compose_config([override])


def test_key_added_with_plus_fails_validation():
    with pytest.raises(ConfigError, match="optim.momentum"):
        validate_config(compose_config(["+optim.momentum=0.9"]))


def test_unknown_group_option_fails():
    with pytest.raises(ConfigCompositionException, match="loss"):
        compose_config(["loss=trpo"])


@pytest.mark.parametrize(
    "override, message",
    [
        ("optim.lr=-1", "optim.lr"),
        ("collector.frames_per_batch=1000", "minibatch"),
        ("collector.total_frames=100", "total_frames"),
        ("env.transforms.obs_norm=whiten", "obs_norm"),
        ("collector.num_envs=3", "num_envs"),
        ("compile=maybe", "compile"),
        ("compile=true loss=kl_ppo", "kl_ppo"),
    ],
)
def test_out_of_range_values_are_config_errors(override, message):
    with pytest.raises(ConfigError, match=message):
        validate_config(compose_config(override.split()))


def test_recipe_v3_is_recipe_v2_and_its_three_pre_registered_values():
    """legged_trot_v3 (issue 72 item 5's pre-registration) = legged_trot_v2 + C2's two weights + the row count the
    rebuild check chose; nothing else differs, so v2's frozen file stays what v3 builds on."""
    from omegaconf import OmegaConf

    def flat(recipe):
        cfg = OmegaConf.to_container(compose_config([f"experiment={recipe}", "env.xml_file=menagerie/unitree_go1/scene.xml"]))

        def walk(node, prefix=""):
            for key, value in node.items():
                if isinstance(value, dict):
                    yield from walk(value, f"{prefix}{key}.")
                else:
                    yield f"{prefix}{key}", value

        return dict(walk(cfg))

    v2, v3 = flat("legged_trot_v2"), flat("legged_trot_v3")
    assert v2.keys() == v3.keys()
    changed = {key: (v2[key], v3[key]) for key in v2 if v2[key] != v3[key]}
    assert changed == {"env.legged.gait_clock_weight": (0.5, 1.5), "env.legged.torque_cost_weight": (0.84, 1.68),
                       "collector.num_envs": (1, 8)}
