"""Issue 59, item 2: observations with a layout (ppo_torchrl/envs/layout.py). Each env declares the named segments of its
observation and how each is scaled; the normalizer holds statistics only and applies the layout, and the layout
travels with the statistics to checkpoints and export. A Go1's terrain heights read a 0.25 l step as 0.25 l
whatever the running statistics saw; a run saved before the layout (one running segment) is normalized as it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from ppo_torchrl.errors import ConfigError
from ppo_torchrl.envs.layout import ObservationLayout, Segment
from ppo_torchrl.envs.normalization import ObservationNormalizer, make_observation_normalizer, obs_scale, standardize

ROOT = Path(__file__).resolve().parents[1]
GO1 = ROOT / "ppo_torchrl" / "assets" / "menagerie" / "unitree_go1" / "scene.xml"
GO1_RUN = ROOT / "results" / "robots" / "legged_2026-11-27" / "go1"


def go1_cfg(*overrides):
    """env=legged on a Go1, its step 2 l ahead (within the 20 height samples, 0.2 l apart), no reset noise."""
    from ppo_torchrl.compose import compose
    from ppo_torchrl.robots.model import read_robot

    l = read_robot(GO1).leg_length
    return compose(["env=legged", f"env.xml_file={GO1}", "env.legged.step_distance=[2.0,2.0]",
                    f"env.terrain.step_height={0.25 * l}", "env.locomotion.reset_noise_scale=0", *overrides]), l


def normalization_of(env):
    from ppo_torchrl.envs.normalization import ObservationNormalization

    return next(t for t in env.transform if isinstance(t, ObservationNormalization))


def test_a_go1_reads_a_quarter_leg_step_inside_the_clip_whatever_the_running_statistics_saw():
    """The running statistics pushed to a std of 1e-5 around a flat-ground observation, for every element (a
    curriculum that never showed a step): the height segment still reads the flat ground ahead as 0 and the
    0.25 l step as 0.25, well inside its clip of 1, on the numpy face and TorchRL's alike; under one running
    normalization over everything (runs saved before issue 59) the same step read as the clip, 10."""
    from ppo_torchrl.envs.state import env_state_of
    from ppo_torchrl.envs.make import make_torchrl_env

    cfg, l = go1_cfg()
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, seed=0)
    state = env_state_of(env)
    norm, batch = state.obs_norm, state.rows.batch  # env=legged: one batched env (tasks/locomotion/batch.py)
    heights = norm.layout.where("terrain_heights")
    assert [s.name for s in norm.layout.segments] == ["proprioception", "foot_contacts", "terrain_heights", "clock"]
    env.reset()
    raw = np.asarray(batch.last_obs[0], np.float64)
    terrain, task = batch.task.terrain, batch.task
    spacing = batch.world.robot.leg_length * cfg.env.legged.height_sample_spacing
    ahead = terrain.along(batch.datas[0].xpos[batch.world.trunk]) + spacing * np.arange(task.height_samples)
    on_step = ahead >= terrain.edge[0]
    assert terrain.height[0] == pytest.approx(0.25 * l) and 0 < on_step.sum() < on_step.size

    flat = raw.copy()
    flat[heights] = raw[heights][0]  # what the statistics saw: flat ground under every sample
    norm.load_state_dict({"mean": flat, "var": np.full(raw.size, 1e-10), "count": 1e6})
    read = norm.apply(raw[None])[0][heights]
    assert read[~on_step] == pytest.approx(0.0, abs=1e-9)
    assert read[on_step] == pytest.approx(0.25, abs=1e-9)
    assert np.abs(read).max() < 1.0  # inside the clip, and a step is not flat
    # TorchRL's face (the eval env's, TorchRL's collectors') reads the same
    torchrl_read = normalization_of(env)._apply_transform(torch.as_tensor(raw[None]))[0].numpy()[heights]
    assert np.array_equal(torchrl_read, read.astype(np.float32))

    whole = ObservationNormalizer((raw.size,), cfg.env.transforms.obs_clip)
    whole.load_state_dict({"mean": flat, "var": np.full(raw.size, 1e-10), "count": 1e6})
    assert (whole.apply(raw[None])[0][heights][on_step] == 10.0).all()  # issue 59's failure: the step is the clip


def test_the_go1_layout_is_derived_from_the_model_and_flags_and_clock_pass_as_they_are():
    from ppo_torchrl.envs.make import make_batch
    from ppo_torchrl.robots.model import read_robot
    from ppo_torchrl.tasks.locomotion.task import HEIGHT_CLIP

    cfg, l = go1_cfg()
    env = make_batch(cfg.env)
    layout = env.observation_layout()
    robot = read_robot(GO1)
    assert layout.where("terrain_heights") == slice(39, 59) and layout.size == env.single_observation_space.shape[0] == 61
    segment = layout.segments[2]
    assert (segment.treatment, segment.offset, segment.scale, segment.clip) == ("fixed", -robot.height, l, HEIGHT_CLIP)
    norm = make_observation_normalizer(cfg.env.transforms, layout.size, layout=layout)
    obs = np.random.default_rng(0).normal(scale=5.0, size=(8, layout.size))
    norm.stats.update(obs)
    out = norm.apply(obs)
    for name in ("foot_contacts", "clock"):  # as they are, bit for bit
        assert np.array_equal(out[:, layout.where(name)], obs[:, layout.where(name)])
    p = layout.where("proprioception")
    scale = obs_scale(norm.stats.var, norm.epsilon)
    assert np.array_equal(out[:, p], standardize(obs, norm.stats.mean, scale, 10.0)[:, p])


def test_the_normalizer_holds_statistics_only_and_env_state_owns_what_each_policy_acts_on():
    from ppo_torchrl.envs.state import EnvState

    norm = ObservationNormalizer((5,), 10.0)
    assert set(vars(norm)) == {"stats", "clip", "epsilon", "enabled", "layout", "_vectors"}
    for name in ("emitted", "replay", "before_reset"):
        assert not hasattr(norm, name)
    state = EnvState([], norm)
    state.emit(np.ones((2, 5), np.float32))
    state.emit(np.zeros((2, 5), np.float32), mask=np.array([False, True]))
    assert state.acted_on().tolist() == [[1.0] * 5, [0.0] * 5]


def test_the_layout_travels_with_the_statistics_through_a_checkpoint_and_export_bakes_the_same_formula(tmp_path):
    """The statistics' state holds the layout; a checkpoint round trip gives it back; export's module (read from
    that state, no env) and the env's normalization (numpy and TorchRL faces) give the same values, bit for bit."""
    from ppo_torchrl.run import checkpoint
    from ppo_torchrl.envs.make import env_spec, make_torchrl_env
    from ppo_torchrl.export import export_policy
    from ppo_torchrl.rl.models import make_actor_critic

    cfg, _ = go1_cfg()
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, seed=0)
    norm = env.transform[0].obs_norm
    rng = np.random.default_rng(1)
    norm.stats.update(rng.normal(size=(64, norm.layout.size)))
    saved = norm.state_dict()
    path = tmp_path / "last.pt"
    checkpoint.save(path, {"actor": {}, "frames": 0, "normalization": {"obs": saved}})
    stats = checkpoint.load(path)["normalization"]["obs"]
    assert ObservationLayout.from_state(stats["layout"], norm.layout.size) == norm.layout

    evaluation = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, obs_stats=stats, train=False)
    ac = make_actor_critic(cfg.policy, env_spec(cfg.env))
    exported = torch.jit.load(str(export_policy(cfg, ac, stats, tmp_path / "policy.pt")))
    obs = rng.normal(scale=0.5, size=(100, norm.layout.size))
    obs[:, norm.layout.where("terrain_heights")] -= 0.27  # heights relative to the trunk, a few beyond the clip
    numpy_face = evaluation.transform[0].obs_norm(obs, update=False)
    torchrl_face = normalization_of(evaluation)._apply_transform(torch.as_tensor(obs)).numpy()
    baked = exported.normalize(torch.as_tensor(obs)).float().numpy()
    assert np.array_equal(numpy_face, torchrl_face) and np.array_equal(numpy_face, baked)
    assert np.array_equal(numpy_face, norm.module()(torch.as_tensor(obs)).float().numpy())
    assert np.abs(numpy_face[:, norm.layout.where("terrain_heights")]).max() == 1.0  # the clip, in l


def test_statistics_saved_for_another_layout_are_refused_and_those_saved_before_layouts_load_into_any():
    layout = ObservationLayout((Segment.running("a", 3), Segment.fixed("b", 2, 0.0, 2.0, 1.0)))
    norm = ObservationNormalizer((5,), 10.0, layout=layout)
    other = ObservationNormalizer((5,), 10.0)
    with pytest.raises(ConfigError, match="layout"):
        norm.load_state_dict(other.state_dict())
    norm.load_state_dict({"mean": np.ones(5), "var": np.ones(5), "count": 3.0})  # an old checkpoint's
    assert norm.stats.count == 3.0
    assert make_observation_normalizer(_transforms(), 5, {"mean": np.ones(5), "var": np.ones(5)}).layout == \
        ObservationLayout.whole(5)


def _transforms():
    from ppo_torchrl.config import TransformsConfig

    return TransformsConfig()


def test_a_legged_run_saved_before_the_layout_is_normalized_as_it_trained():
    """A legged config without env.legged.obs_layout (saved before issue 59) keeps one running normalization over the
    whole observation and world heights; its statistics (saved without a layout) normalize exactly by the one
    formula. env=legged and recipe v2 (experiment=legged_trot_v2) set segments; issue 46's frozen legged_trot pins whole."""
    from omegaconf import OmegaConf

    from ppo_torchrl.compose import compose
    from ppo_torchrl.envs.make import make_batch

    cfg, _ = go1_cfg()
    assert cfg.env.legged.obs_layout == "segments"
    assert compose(["experiment=legged_trot_v2", f"env.xml_file={GO1}"]).env.legged.obs_layout == "segments"
    frozen = compose(["experiment=legged_trot", f"env.xml_file={GO1}"]).env.legged
    assert (frozen.obs_layout, frozen.contacts, frozen.physics_dt) == ("whole", "model", "model")
    saved = OmegaConf.create(OmegaConf.to_container(cfg))
    del saved.env.legged["obs_layout"]  # as a run dir's config.yaml saved before the key
    from ppo_torchrl.config import Config

    saved = OmegaConf.merge(OmegaConf.structured(Config), saved)  # as config.run_config reads it back
    env = make_batch(saved.env)
    assert env.observation_layout() == ObservationLayout.whole(61)
    obs = env.reset(seed=0)[0][0]
    trunk, task = env.datas[0].xpos[env.world.trunk], env.task
    points = trunk[None, None, :2] + task._offsets[None, :, None] * env.world.heading  # 10 cm apart along the heading
    assert obs[39:59].tolist() == task.terrain.height_at(slice(0, 1), points)[0].tolist()  # world heights (whole)
    layout = env.observation_layout()
    rng = np.random.default_rng(2)
    stats = {"mean": rng.normal(size=61), "var": rng.uniform(1e-6, 2.0, size=61), "count": 10.0}
    norm = make_observation_normalizer(saved.env.transforms, 61, stats, frozen=True, layout=layout)
    x = rng.normal(scale=3.0, size=(7, 61))
    assert np.array_equal(norm.apply(x), standardize(x, stats["mean"], obs_scale(stats["var"], 1e-8), 10.0))


@pytest.mark.skipif(not (GO1_RUN / "checkpoints" / "last.pt").is_file(), reason="the go1 report run is not here")
def test_the_go1_report_run_is_evaluated_with_the_normalization_it_trained_with():
    """results/robots/legged_2026-11-27/go1 (trained before issue 59): its config has no obs_layout and its statistics
    no layout, so its evaluation env normalizes the whole observation by its running statistics, as it trained."""
    from ppo_torchrl.run.checkpoint import load_policy
    from ppo_torchrl.envs.state import env_state_of
    from ppo_torchrl.envs.make import make_torchrl_env

    cfg, _, state = load_policy(GO1_RUN, str(GO1_RUN / "checkpoints" / "last.pt"))
    stats = state["normalization"]["obs"]
    assert cfg.env.legged.obs_layout == "whole" and "layout" not in stats
    env = make_torchrl_env(cfg.env, clip_actions=True, gamma=0.99, obs_stats=stats, train=False)
    norm = env_state_of(env).obs_norm
    assert norm.layout == ObservationLayout.whole(len(stats["mean"])) and norm.coefficients()[2] == 10.0
