"""Typed schemas for every config group, registered in Hydra's ConfigStore.

`conf/config.yaml` starts from `base_config`, so a misspelt key or a value of the wrong type fails
when the config is composed, before any environment is built. Each group in `conf/` has one
dataclass here, named like the module that consumes it (`loss` -> `losses.py`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import MISSING, OmegaConf


@dataclass
class TransformsConfig:
    """Per-step env transforms (envs.py). Logged returns are always the raw ones."""

    # running: VecNorm-style running mean/std; fixed: ObservationNorm with stats from initial
    # random rollouts; none: raw observations.
    obs_norm: str = "running"
    obs_norm_init_frames: int = 1000  # frames of random rollouts that set the `fixed` stats
    # return: divide by the std of the discounted return (gym NormalizeReward / SB3 VecNormalize);
    # scale: multiply by `reward_scale` (TorchRL RewardScaling); none: raw rewards.
    reward_norm: str = "return"
    reward_scale: float = 1.0
    obs_clip: Optional[float] = 10.0  # clip normalized observations to [-obs_clip, obs_clip]
    reward_clip: Optional[float] = 10.0  # clip normalized rewards to [-reward_clip, reward_clip]
    norm_epsilon: float = 1e-8
    # Your own TorchRL transforms: Hydra `_target_` entries, instantiated and appended (after the
    # normalization, before the reward scaling) to the training and the evaluation TransformedEnv, e.g.
    # '[{_target_: torchrl.envs.CatFrames, N: 3, dim: -1, in_keys: [observation]}]'. They need
    # collector.backend=torchrl (auto picks it); a changed observation size reaches the networks.
    extra: List[Any] = field(default_factory=list)


@dataclass
class CommandConfig:
    """What the robot is told to do (tasks/locomotion/commands.py). heading: walk along the heading at up to
    env.legged.target_speed (the climb recipes'). velocity: a joystick, a commanded forward and sideways velocity in
    the trunk's heading frame and a yaw rate, each drawn uniformly per row from its range and drawn again every
    `resample` (a [min, max] time, drawn too), a `stand_share` of the draws all zero; given to the policy as an
    observation segment. Ranges in the robot's units (env=legged: sqrt(g l) for speeds, sqrt(g / l) for the yaw rate,
    sqrt(l / g) for times; robots/recipe.py turns them into SI; env=mjcf takes them in SI)."""

    kind: str = "heading"  # heading | velocity
    vx: List[float] = field(default_factory=lambda: [-0.5, 0.5])
    vy: List[float] = field(default_factory=lambda: [-0.25, 0.25])
    yaw: List[float] = field(default_factory=lambda: [-0.25, 0.25])
    stand_share: float = 0.05
    resample: List[float] = field(default_factory=lambda: [15.0, 45.0])
    # the tracking terms' widths: exp(-error^2 / sigma), error in the units above (Playground's Go1: 0.25 (m/s)^2
    # and 0.25 (rad/s)^2, which are ~0.06 and ~0.011 in a Go1's units)
    sigma_lin: float = 0.06
    sigma_yaw: float = 0.011


@dataclass
class RandomizeConfig:
    """Randomized physics (tasks/locomotion/randomize.py), drawn per row at each reset from these ranges (uniform)
    and recorded with the episode (evaluate can replay a draw). The defaults randomize nothing. In the robot's units
    for env=legged (lengths in l, speeds in sqrt(g l), times in sqrt(l / g); robots/recipe.py turns them into SI),
    in SI for env=mjcf; scales are dimensionless."""

    friction: List[float] = field(default_factory=lambda: [1.0, 1.0])  # x every geom's friction: the grip
    trunk_mass: List[float] = field(default_factory=lambda: [1.0, 1.0])  # x the trunk's mass and inertia
    com: float = 0.0  # the trunk's centre of mass moved by up to this along each axis (x l)
    strength: List[float] = field(default_factory=lambda: [1.0, 1.0])  # x every servo's gains (its torque)
    push_speed: float = 0.0  # a push: up to this ground velocity added to the trunk (x sqrt(g l)); 0: none
    push_interval: List[float] = field(default_factory=lambda: [5.0, 70.0])  # time between pushes (x sqrt(l / g))
    # observation noise, a level: uniform noise of level x (0.02 on the trunk's height and attitude, 0.03 rad on the
    # joint angles, 0.05 sqrt(g l) on its linear and 0.04 sqrt(g / l) on its angular velocity, 0.3 sqrt(g / l) on
    # the joint speeds) on what the policy sees; 0: none
    obs_noise: float = 0.0
    delay_share: float = 0.0  # the share of episodes whose actions reach the drives one control step late


@dataclass
class LocomotionConfig:
    """An MJCF locomotion env (env=mjcf; tasks/locomotion/): Gymnasium Ant-v5's reward and termination knobs,
    then heading, actuator limits and legged-locomotion reward terms (defaults: off, Ant-v5's behaviour)."""

    forward_reward_weight: float = 1.0  # x velocity of main_body, m/s
    healthy_reward: float = 1.0  # per step while main_body's z is inside healthy_z_range
    healthy_z_range: List[float] = field(default_factory=lambda: [0.2, 1.0])
    # Read healthy_z_range above the terrain under main_body (a step env: the step's top beyond its edge)
    # instead of Ant-v5's world z, with which a fall line of 20 cm is 5 cm above a 15 cm step.
    healthy_z_above_terrain: bool = False
    terminate_when_unhealthy: bool = True  # the episode ends when the robot falls
    ctrl_cost_weight: float = 0.5  # times sum(action^2)
    contact_cost_weight: float = 5e-4  # times sum(clipped external contact forces^2)
    frame_skip: int = 5  # physics steps per action: control at 1 / (timestep * frame_skip) Hz
    reset_noise_scale: float = 0.1  # uniform noise on qpos, normal on qvel, at reset
    main_body: str = "1"  # body name or id whose x velocity is rewarded and z is checked
    contact_forces_in_observation: bool = False  # append cfrc_ext to the observation
    # Which way is forward: the forward reward and eval's forward velocity are main_body's velocity
    # along this ground direction. x (Gymnasium's: +x of the world), -x, y, -y, an angle in degrees
    # counterclockwise from +x, or auto: main_body's own +x axis in the model's initial pose.
    heading: str = "x"
    # The forward reward counts speed up to this (m/s) and no more; null: all of it (Gymnasium's).
    target_speed: Optional[float] = None
    # Actuators (each must drive a joint; null: as the model file has them); tasks/locomotion/world.py says why.
    torque_limit: Optional[float] = None  # N m: every actuator's peak joint torque (its forcerange)
    # rad/s: the drive's torque-speed line, net driving torque <= torque_limit x (1 - speed / this):
    # joint damping of torque_limit / joint_speed_limit on each actuated joint (a motor's back-EMF,
    # integrated implicitly), so no actuator drives its joint past this speed. Needs a torque limit.
    joint_speed_limit: Optional[float] = None
    kp: Optional[float] = None  # N m/rad: stiffness of the position actuators (the P of the PD servo)
    kd: Optional[float] = None  # N m s/rad: their damping (the D of the servo, inside the torque limit)
    armature: Optional[float] = None  # kg m^2: reflected rotor inertia of each actuated joint
    # Legged-locomotion reward terms (legged_gym's set), per control step, each times its weight (0: off):
    torque_cost_weight: float = 0.0  # - w x sum of actuator torque^2 (N^2 m^2)
    joint_speed_cost_weight: float = 0.0  # - w x sum of actuated joint speed^2 ((rad/s)^2)
    # - w x sum over actuated joints of how far (rad/s) each went past joint_speed_limit at its fastest
    # physics step of the control step (legged_gym's dof_vel_limits; impacts, not the drive, do that)
    joint_speed_limit_cost_weight: float = 0.0
    action_rate_cost_weight: float = 0.0  # - w x sum of (action - previous action)^2
    foot_slip_cost_weight: float = 0.0  # - w x sum over feet on the ground of their horizontal speed^2 ((m/s)^2)
    base_height_cost_weight: float = 0.0  # - w x (main_body's height above the terrain - base_height_target)^2
    base_height_target: Optional[float] = None  # m; null: main_body's height in the model's initial pose
    orientation_cost_weight: float = 0.0  # - w x (1 - cos of main_body's tilt from its initial attitude)
    body_contact_cost_weight: float = 0.0  # - w x number of geoms of non-foot bodies (trunk, thighs) on the ground
    feet_air_time_weight: float = 0.0  # + w x sum, over feet touching down, of (time in the air - feet_air_time_target)
    feet_air_time_target: float = 0.5  # s: swings shorter than this cost, longer ones pay (legged_gym: 0.5)
    # A trot clock (four-footed robots): a phase that runs from 0 to 1 every gait_period seconds from each
    # episode's start, given to the policy as sin and cos; the diagonal pair LF+RH is meant to be down in the
    # first half of the period and RF+LH in the second. null: no clock. gait_clock_weight: + w x the share of
    # feet whose contact matches that schedule (a periodic reward, Siekmann et al. 2021).
    gait_period: Optional[float] = None
    gait_clock_weight: float = 0.0
    # A swing held too long: - w x the share of feet that have been in the air longer than long_swing_limit (s),
    # each control step (a trot's swing lasts about half its period; a foot held up is not a trot). 0: off.
    long_swing_cost_weight: float = 0.0
    long_swing_limit: float = 0.5
    # A stumble: - w x the share of feet touching the ground or the step on a face more than 45 degrees from level
    # (the step's riser, its edge met low; legged_gym's feet_stumble from the contact's normal). 0: off.
    stumble_cost_weight: float = 0.0
    # A world that is not the one trained on (evaluate's robustness figures, issue 59): every contact's friction
    # (each geom's, the feet's and the floor's: MuJoCo takes the larger of a pair) and the main body's mass and
    # inertia, each x this.
    friction_scale: float = 1.0
    trunk_mass_scale: float = 1.0
    # Floor each step's reward at 0 (legged_gym's only_positive_rewards): while the costs outweigh the
    # forward and healthy rewards (early, exploring), ending the episode by a fall does not pay.
    only_positive_rewards: bool = False
    # Bodies (names) whose touching the ground or the step ends the episode, as legged_gym's
    # terminate_after_contacts_on (e.g. [trunk]); on top of healthy_z_range. Empty: off.
    terminate_on_contact: List[str] = field(default_factory=list)
    # The feet (geom names), for contacts, slip, air time and gait figures; empty: the geoms whose name
    # contains "foot", else every geom of a body without child bodies.
    foot_geoms: List[str] = field(default_factory=list)
    # What the robot is told to do (CommandConfig, in SI here; env=legged derives it from env.legged.command)
    command: CommandConfig = field(default_factory=CommandConfig)
    randomize: RandomizeConfig = field(default_factory=RandomizeConfig)  # in SI here (env=legged: env.legged.randomize)
    # The weights of the named reward terms without a key of their own ({term: weight}; env=legged: env.legged.rewards)
    rewards: Dict[str, float] = field(default_factory=dict)


@dataclass
class TerrainConfig:
    """The step of a step env, set per episode, and what the policy perceives (tasks/locomotion/terrain.py).

    Step keys need a model with a body named `step` holding one box geom (env=quadruped_step); with
    none of them set the step stays where the model file puts it. The observation keys work on any model.
    """

    step_height: Optional[float] = None  # m: every episode's step height (wins over the range and curriculum)
    step_height_range: Optional[List[float]] = None  # [min, max] m: each episode's height is drawn uniformly
    # Draw from [min, level] instead, level starting at min and rising by curriculum_step (up to max)
    # each time the success rate of the last curriculum_window training episodes reaches curriculum_threshold.
    curriculum: bool = False
    curriculum_threshold: float = 0.8
    curriculum_window: int = 20  # episodes
    curriculum_step: float = 0.02  # m
    # Narrow it again by curriculum_step when that success rate falls to this or below (legged_gym moves
    # a robot down a level as well as up); null: the level only rises.
    curriculum_down_threshold: Optional[float] = None
    # m: with a curriculum, draw each height from [level - band, level] (not below min) rather than
    # from [min, level], so training stays at the hard end; null: the whole of [min, level].
    curriculum_band: Optional[float] = None
    # With a band: the share of episodes drawn from the band; the others come from the whole of
    # [min, level], so low steps and flat ground are not forgotten. 1: the band only.
    curriculum_band_share: float = 1.0
    # The share of training episodes on flat ground (the step at 0 m), drawn before the range and the
    # curriculum; they do not count towards the curriculum's success rate. 0: none (the range's own
    # draws only). Without it a curriculum at 20 cm seldom shows the policy flat ground.
    flat_share: float = 0.0
    step_distance: Optional[List[float]] = None  # [min, max] m from main_body's start to the edge, drawn per episode
    success_margin: float = 0.5  # m: an episode succeeds when main_body ends this far beyond the edge
    # Evaluation envs (periodic eval, evaluate): this fixed height unless step_height is set; null:
    # drawn from step_height_range over its whole width (no curriculum in eval).
    eval_step_height: Optional[float] = None
    observe_contacts: bool = False  # append a 0/1 ground-contact flag per foot to the observation
    # Append the terrain height (m, from the known step geometry: the step's top beyond its edge, else
    # 0) at this many points along +x, height_sample_spacing apart, the first under main_body. 0: blind.
    height_samples: int = 0
    height_sample_spacing: float = 0.1  # m


@dataclass
class LeggedConfig:
    """env=legged: a robot read from its model (robots/model.py) and the recipe's targets, each in the
    robot's own units (robots/recipe.py turns them into env.locomotion and env.terrain values): lengths
    in leg lengths l, speeds in sqrt(g l), times in sqrt(l / g), torques in m g l. No number here
    belongs to one robot."""

    keyframe: Optional[str] = None  # the standing pose: this keyframe, else the model's 'home', else qpos0
    # rad: each joint's target is its standing angle + action_scale x action (in [-1, 1]), or, with
    # saturation_cap, + its servo's saturation angle (peak torque / kp, from the model) x action where that is
    # smaller. The cap (on for a bare env=legged, and for run dirs saved before the key existed) keeps random
    # actions gentle on weak servos but also the reach: Go1's feet then rise at most 0.24 l, under the step.
    # experiment=legged_trot turns it off and explores gently with the policy's initial std instead.
    action_scale: float = 0.5
    saturation_cap: bool = True
    control_dt: float = 0.02  # s: the policy acts every control_dt (frame_skip = control_dt / the physics step)
    # terrain: the robot's geoms touch the floor and the step only (robot-robot contacts only for the model's
    # <pair>s; conf/env/legged.yaml sets it); model: every contact the model's contype/conaffinity allow,
    # self-collisions included (runs saved before the key existed trained so, and are evaluated so).
    # robots/model.py, filter_contacts.
    contacts: str = "model"
    # The physics step: rule (robots/recipe.py, rule_dt: the longest step dividing control_dt that keeps the model's
    # contacts as soft as it says, its stiffest servo accurate and explicit damping stable; conf/env/legged.yaml),
    # model (the model's own timestep: runs saved before the key existed trained so), or a step in seconds.
    physics_dt: str = "model"
    # The contacts' friction cone: model (the model's own; Menagerie's robots: elliptic), pyramidal (2.4x the physics'
    # rate on Go1, a different friction model: results/speed/physics_options_2026-12-03/) or elliptic.
    friction_cone: str = "model"
    target_speed: float = 0.35  # x sqrt(g l): the forward reward counts speed up to this
    forward_reward_weight: float = 3.5  # per sqrt(g l) of forward speed
    fall_height: float = 0.4  # x l: the trunk below this (m above the floor) is a fall
    too_high: float = 2.5  # x l: the trunk above this ends the episode too
    gait_period: Optional[float] = 2.66  # x sqrt(l / g): the trot clock's period; null: no clock
    gait_clock_weight: float = 0.5
    long_swing_cost_weight: float = 0.0  # - w x the share of feet in the air longer than long_swing_limit
    long_swing_limit: float = 2.0  # x sqrt(l / g): 0.75 of the trot clock's period (0.42 s for a Go1, 0.49 s ANYmal B)
    stumble_cost_weight: float = 0.0  # - w x the share of feet on an upright face (the step's riser): dimensionless
    torque_cost_weight: float = 0.42  # x sum (torque / (m g l))^2
    friction_scale: float = 1.0  # x every contact's friction: the grip (the robustness figure: 0.5)
    trunk_mass_scale: float = 1.0  # x the trunk's mass and inertia (the robustness figure: 1.1)
    joint_speed_cost_weight: float = 0.02  # x sum (joint speed x sqrt(l / g))^2
    foot_slip_cost_weight: float = 0.25  # x sum over feet down of (foot speed / sqrt(g l))^2
    base_height_cost_weight: float = 1.25  # x ((trunk height above the ground - its standing height) / l)^2
    step_height: float = 0.25  # x l: the step evaluation climbs (evaluate with no heights=)
    step_height_range: List[float] = field(default_factory=lambda: [0.0, 0.4])  # x l: training's range
    curriculum_step: float = 0.04  # x l
    curriculum_band: Optional[float] = 0.08  # x l
    step_distance: List[float] = field(default_factory=lambda: [2.0, 4.0])  # x l: the step's edge from the start
    success_margin: float = 1.0  # x l beyond the edge: crossed
    height_sample_spacing: float = 0.2  # x l
    # How each part of the observation is scaled (layout.py; tasks/locomotion/task.py, LeggedTask.layout). segments:
    # proprioception by the running statistics, the contact flags and the trot clock as they are, the terrain
    # heights relative to the trunk's standing height in l with a fixed clip, so a step reads its height whatever
    # the curriculum showed (conf/env/legged.yaml sets it). whole: one running normalization over everything,
    # heights in world m: runs saved before the key existed (issue 59) trained so, and are evaluated so.
    obs_layout: str = "whole"
    # The frame the trunk's attitude and linear velocity are observed in (tasks/locomotion/task.py, heading_frame).
    # world: as Ant-v5 gives them (its quaternion, its world-frame velocity; every run before the key). heading:
    # the trunk's own yaw taken out of both (a roll-and-pitch quaternion, the velocity in the heading frame the
    # joystick's command is given in), so the policy reads the same state whichever way the robot faces.
    obs_frame: str = "world"
    # step: a step across the path, its height from the curriculum in training and step_height in evaluation (the
    # climb recipes'); flat: flat ground, no step (the joystick's)
    terrain: str = "step"
    command: CommandConfig = field(default_factory=CommandConfig)
    randomize: RandomizeConfig = field(default_factory=RandomizeConfig)
    # The weights of the named reward terms that have no key of their own (tasks/locomotion/rewards.py, e.g. the
    # joystick's tracking_lin_vel): {term: weight}, dimensionless (each such term reads its quantity in the robot's
    # units). A name that is not a registered term is refused.
    rewards: Dict[str, float] = field(default_factory=dict)


@dataclass
class PlaygroundConfig:
    """env=playground: a MuJoCo Playground task as EnvPool ships it (its C++ port; envs_playground.py). env.id is the
    task's EnvPool id (Go1JoystickFlatTerrain-v1), env.make_kwargs its EnvPool settings (noise_level, kp, ...),
    env.max_episode_steps its time limit (null: the task's own)."""

    # The keys of the task's dict observation: the actor's (policy.critic_obs=observation: the critic's too), and the
    # one policy.critic_obs=privileged gives the critic (as privileged_observation). A task whose observation is one
    # vector gives it all to the actor and has no privileged one.
    observation_key: str = "state"
    privileged_key: str = "privileged_state"
    # EnvPool's num_threads, the C++ threads that step a training run's pool (one pool of collector.num_envs per
    # collector process); null: min(collector.num_envs, the CPUs this process may use).
    threads: Optional[int] = None


@dataclass
class EnvConfig:
    """Which Gymnasium environment to train on (envs.py)."""

    id: str = MISSING  # a registered Gymnasium continuous-control id, e.g. Hopper-v4
    max_episode_steps: Optional[int] = None  # None: the id's registered time limit
    make_kwargs: Dict[str, Any] = field(default_factory=dict)  # extra gymnasium.make kwargs
    # env=mjcf: the robot's MJCF file, run as a locomotion env (Gymnasium's Ant-v5 class). A path, or
    # the name of a model shipped in ppo_torchrl/assets (quadruped.xml, quadruped_step.xml, quadruped_a1like.xml,
    # quadruped_a1like_step.xml).
    xml_file: Optional[str] = None
    locomotion: LocomotionConfig = field(default_factory=LocomotionConfig)
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    # env=legged: the robot of xml_file read from its model and the recipe scaled to it; null: not a legged env
    legged: Optional[LeggedConfig] = None
    # env=playground: a MuJoCo Playground task stepped by EnvPool; null: not one
    playground: Optional[PlaygroundConfig] = None
    transforms: TransformsConfig = field(default_factory=TransformsConfig)


@dataclass
class PolicyConfig:
    """Actor and critic networks (models.py)."""

    # tanh_normal: TanhNormal squashed into the action bounds; normal: Normal whose sample is
    # clipped to the bounds before it reaches the env (the stored action stays unclipped).
    head: str = "normal"
    # state_independent: a learned log-std vector; state_dependent: softplus of a network output.
    std: str = "state_independent"
    log_std_init: float = 0.0
    std_min: float = 0.0  # floor added under the std; 0 disables it
    # A cap on the std (std_min included): the learned std stops there, and so does the entropy bonus's pull on
    # it (no gradient past the cap). null: no cap (an entropy bonus can grow the std without bound).
    std_max: Optional[float] = None
    # Hidden layers of the actor (and of the shared trunk) and of the critic: their number and widths.
    hidden_sizes: List[int] = field(default_factory=lambda: [64, 64])
    critic_hidden_sizes: List[int] = field(default_factory=lambda: [64, 64])
    # When set, it wins: every hidden layer of actor and critic gets this width and the lists above
    # give only the number of layers (conf/env/Hopper-v4.yaml sets 128: a 128-128 actor and critic
    # although hidden_sizes reads [64, 64]). null: the lists apply as written.
    width: Optional[int] = None
    activation: str = "tanh"  # tanh | relu | elu
    # What the critic reads: observation (the actor's input, the default) or privileged (an asymmetric critic: the env's
    # privileged observation, e.g. a Playground task's privileged_state, under the batch key privileged_observation
    # with normalization statistics of its own; the actor still reads the observation alone, and export carries it).
    critic_obs: str = "observation"
    shared_trunk: bool = False  # one trunk (hidden_sizes) with a policy head and a value head
    ortho_init: bool = True  # orthogonal init, gain sqrt(2) hidden, policy_head_gain, value_head_gain
    policy_head_gain: float = 0.01
    value_head_gain: float = 1.0


@dataclass
class LossConfig:
    """Which TorchRL loss module, and how many passes over each batch (losses.py)."""

    name: str = "clip_ppo"  # clip_ppo | kl_ppo | ppo | a2c | reinforce
    epochs: int = 10
    minibatch_size: Optional[int] = 64  # None: the whole batch is one minibatch
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.0
    critic_coef: float = 0.5
    critic_loss: str = "l2"  # l2 | l1 | smooth_l1
    clip_value: Optional[float] = None  # clipped value loss range (PPO2-style); None disables
    normalize_advantage: bool = True  # per minibatch
    kl_target: float = 0.01  # kl_ppo: target KL (dtarg)
    kl_beta: float = 1.0  # kl_ppo: initial KL penalty coefficient
    # Early stop of the update (CleanRL's target_kl): once an epoch's mean approximate KL to the collecting policy
    # passes this, the batch's remaining epochs are skipped (train/epochs logs how many ran). null: every epoch.
    stop_kl: Optional[float] = None
    entropy_samples: int = 1  # Monte-Carlo samples where entropy has no closed form (TanhNormal)


@dataclass
class AdvantageConfig:
    """Advantage estimator (advantage.py)."""

    name: str = "gae"
    gamma: float = 0.99
    lmbda: float = 0.95
    # Advantages (and value targets) computed again before every epoch after the first, with the critic as the
    # update has left it ("What Matters in On-Policy RL", Andrychowicz et al. 2020; Tianshou's recompute_advantage).
    # The old values that value clipping reads stay the collected ones. false: once per batch (TorchRL's, SB3's).
    recompute: bool = False


@dataclass
class OptimConfig:
    """Optimizer and learning-rate schedule (trainer.py)."""

    name: str = "adam"  # adam | adamw
    lr: float = 3e-4
    anneal_lr: bool = True  # linear decay to 0 over total_frames
    eps: float = 1e-5
    weight_decay: float = 0.0
    max_grad_norm: Optional[float] = 0.5


@dataclass
class CollectorConfig:
    """How frames are gathered (collectors/)."""

    frames_per_batch: int = 2048
    total_frames: int = 1_000_000
    num_envs: int = 1
    # torchrl: torchrl.collectors.Collector over TransformedEnv(GymWrapper), the reference pipeline;
    # fast: the same pipeline's math in a lean numpy loop over the same gymnasium envs (same batch keys,
    # same statistics); auto: fast unless env.transforms.extra asks for TorchRL transforms; envpool (an option,
    # the `envpool` extra): fast's loop over EnvPool, the Gymnasium MuJoCo ids stepped in C++ (a resume starts
    # new episodes: collectors/envpool_backend.py).
    backend: str = "auto"
    # Worker processes, each stepping num_envs envs built from this config: > 1 runs TorchRL's
    # MultiSyncCollector (collectors/multiprocess.py). A batch stays frames_per_batch on-policy frames
    # (frames_per_batch / workers from each), the weights go to every worker after each update, and
    # the workers' normalization statistics are merged into one set after each batch.
    workers: int = 1
    # env=legged (one batched env of num_envs robots): the threads its physics steps on (MuJoCo releases the GIL in
    # each row's step); 0: one per core, at most one per robot; each worker process of workers > 1 uses one.
    physics_threads: int = 0
    # null: local processes; ray: TorchRL's RayCollector with `workers` remote collectors
    # (pip install -e ".[ray]"), on a local ray.init() unless ray_address joins a cluster (auto: the
    # one `ray start` runs on this node; or host:port).
    distributed: Optional[str] = None
    ray_address: Optional[str] = None


@dataclass
class LoggerConfig:
    """Experiment logger (report.py reads metrics.csv, which every run writes)."""

    name: str = "csv"  # csv | tensorboard | wandb | mlflow | none (TorchRL loggers; metrics.csv is always written)
    project: str = "ppo_torchrl"
    print_every_s: float = 10.0  # progress line period when stdout is not a TTY


@dataclass
class EvalConfig:
    """Deterministic evaluation on a separate env with frozen normalization stats (evaluate.py)."""

    every_frames: int = 100_000  # 0 disables periodic eval
    episodes: int = 5
    final_episodes: int = 10  # at the end of training; 0 disables
    deterministic: bool = True
    video: bool = False  # film each eval into <run dir>/videos/eval_<frames>.mp4 (MUJOCO_GL=egl), in real time
    video_episodes: List[int] = field(default_factory=lambda: [0])  # which episodes of an eval, from 0: one mp4
    video_length: Optional[float] = None  # at most this many (simulated) seconds of video; null: whole episodes
    # Also report the share of episodes that end beyond this x (m). A step env (a model with a `step`
    # body) reports its own instead: the main body env.terrain.success_margin beyond the step's edge.
    success_x: Optional[float] = None
    # Periodic evals in a second process (eval_worker.py) while training goes on: auto | true | false.
    # auto: runs of >= 150k frames in a process allowed >= 2 CPUs. metrics.csv reads the same either way.
    background: str = "auto"


@dataclass
class CheckpointConfig:
    """What is saved under <run dir>/checkpoints (checkpoint.py)."""

    every_frames: int = 100_000
    keep_last: int = 3
    save_best: bool = True


@dataclass
class Config:
    env: EnvConfig = field(default_factory=EnvConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    advantage: AdvantageConfig = field(default_factory=AdvantageConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    logger: LoggerConfig = field(default_factory=LoggerConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    checkpoint: CheckpointConfig = field(default_factory=CheckpointConfig)
    seed: int = 1
    device: str = "cpu"  # cpu | cuda | auto: networks and the update; the simulator stays on CPU
    torch_threads: int = 1  # small MLPs run fastest single-threaded
    # torch.compile the whole minibatch step (loss, gradients, clip, Adam: minibatch.FusedStep): auto |
    # true | false. auto compiles runs of >= 150k frames, where the one-off compile (~20 s cold, a few s
    # once cached) is repaid: the update runs ~3.5-4x faster than with the loss alone compiled.
    compile: str = "auto"
    resume: Optional[str] = None  # a run dir: continue it from checkpoints/last.pt
    # A new run refuses a dir that holds another run (hydra.run.dir / hydra.sweep.dir given twice);
    # overwrite=true removes that run's files first. A dir in use by a running process is always refused.
    overwrite: bool = False
    # Transfer: start a new run from another run's weights and normalization stats (its best.pt, or
    # a checkpoint file); init_from_optimizer also takes its optimizer state.
    init_from: Optional[str] = None
    init_from_optimizer: bool = False
    # With -m hparams_search=<file>: a tag added to the Optuna study's name, which already holds the
    # search file, env id and total_frames (conf/hparams_search), to keep apart studies they don't tell apart.
    hparams_search_name: Optional[str] = None
    # Several seeds per run, for a study whose objective is a mean over seeds (hparams_search=optuna_seeds):
    # the run trains each seed in turn into <run dir>/seed<k>/ and returns the mean of their objectives,
    # written with the per-seed figures to <run dir>/trial.json. [] (the default): one run of `seed`.
    trial_seeds: List[int] = field(default_factory=list)
    # With trial_seeds: stop the trial after a seed whose objective is below this (Optuna's ThresholdPruner
    # `lower`, per seed); the seeds after it are not trained and the trial's value is the mean of those that
    # were. For a study on a small budget: e.g. half the worst seed of the best trial so far. null: never.
    trial_prune_below: Optional[float] = None


def study_name(*parts) -> str:
    """`${ppo.study_name:optuna,Hopper-v4,1000000frames,null}` -> optuna_Hopper-v4_1000000frames."""
    return "_".join(str(part) for part in parts if part is not None)


def register_configs() -> None:
    cs = ConfigStore.instance()
    cs.store(name="base_config", node=Config)
    OmegaConf.register_new_resolver("ppo.study_name", study_name, replace=True)


register_configs()


def run_config(run_dir, state: dict, announce: bool = False):
    """A run's config, from its checkpoint (which holds the resolved config it trained with): `config.yaml`
    can be damaged or edited by hand, and filling its missing keys with defaults would train or evaluate
    another config. When config.yaml disagrees, one warning line says which was used."""
    import sys
    from pathlib import Path

    from ppo_torchrl.config_data import plain, read_yaml
    from ppo_torchrl.errors import ConfigError

    saved = state.get("config")
    if not isinstance(saved, dict):
        raise ConfigError(f"the checkpoint of {run_dir} holds no config; it was not made by ppo_torchrl's trainer")
    plain(saved, f"the checkpoint of {run_dir}'s config")  # data: an interpolation in it is refused, never resolved
    cfg = OmegaConf.merge(OmegaConf.structured(Config), OmegaConf.create(saved))
    if announce:
        try:
            same = read_yaml(Path(run_dir) / "config.yaml") == saved
        except Exception:  # noqa: BLE001 - missing, truncated, not YAML or not data: the checkpoint's config is used
            same = False
        if not same:
            print(f"warning: {Path(run_dir) / 'config.yaml'} is missing, damaged or differs from the checkpoint's "
                  "config; using the checkpoint's", file=sys.stderr, flush=True)
    return cfg
