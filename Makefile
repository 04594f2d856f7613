# Two commands for a fresh checkout: `make train` and `make test`. Both create .venv when missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup train test bench trot robot clean

setup: $(STAMP)

# The CPU wheel of torch first and pinned: an unpinned torch would pull several GB of CUDA packages.
# A GPU machine: TORCH="torch==2.13.0 --index-url <CUDA wheel index>"; offline: PIP_FLAGS="--no-index --find-links <dir>"
# (docs/speed.md, "On a GPU").
TORCH ?= torch==2.13.0
PIP_FLAGS ?=
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip $(PIP_FLAGS) || test -n "$(PIP_FLAGS)"
	$(PY) -m pip install --quiet $(PIP_FLAGS) $(TORCH)
	$(PY) -m pip install --quiet $(PIP_FLAGS) -e ".[test,loggers,sweeps,envpool,deploy]"
	touch $(STAMP)

# make exits 2 whenever a recipe fails; a run stopped by a signal (exit 128 + n: Ctrl-C 130) stops make by
# the same signal, so `make train` ends with the code the app gave (README: exit codes).
train: $(STAMP)
	@echo MUJOCO_GL=egl $(PY) -m ppo_torchrl env=Hopper-v4 $(ARGS)
	@MUJOCO_GL=egl $(PY) -m ppo_torchrl env=Hopper-v4 $(ARGS); rc=$$?; \
		if [ $$rc -gt 128 ]; then kill -$$((rc - 128)) $$PPID; fi; exit $$rc

# pytest exits 5 when it collects nothing; that is a failure here, never a silent pass.
# -n 2: two test processes (pytest-xdist), one per core of the 2-core CI machine.
test: $(STAMP)
	$(PY) -m pytest -q -n 2 $(ARGS)

# The quadruped's trot recipe (issue 31), one training seed in two stages: 10M frames of experiment=quadruped_trot
# in TROT_DIR/seed<k>_stage1, then 2M of experiment=quadruped_trot_finetune in TROT_DIR/seed<k>, from the first
# stage's last checkpoint, as the recipe was tuned (a run dir would give its best.pt, the in-training evals' pick).
# A stage a kill stopped is resumed from its checkpoint; a finished one is kept. ARGS: more overrides for both
# stages (e.g. ARGS="env=quadruped_a1like_step env.locomotion.healthy_z_range=[0.12,1.0]").   make trot SEED=11
TROT_DIR ?= outputs/trot
STAGE1 = $(TROT_DIR)/seed$(SEED)_stage1
trot: $(STAMP)
	@test -n "$(SEED)" || { echo "error: make trot needs SEED=<k> (the training seed)" >&2; exit 2; }
	$(call stage,$(STAGE1),experiment=quadruped_trot seed=$(SEED) $(ARGS))
	$(call stage,$(TROT_DIR)/seed$(SEED),experiment=quadruped_trot_finetune seed=$(SEED) \
		init_from=$(STAGE1)/checkpoints/last.pt $(ARGS))

# A robot read from its model under a legged recipe (RECIPE: legged_trot, issue 46's, frozen; legged_trot_v2, issue 59's)
# on XML in ROBOT_DIR (resumed when a kill stopped it, kept when finished), then its height sweep from the last
# checkpoint, EPISODES per height at HEIGHTS (in leg lengths l) on episode seeds SWEEP_SEED * 1000 + i, in
# ROBOT_DIR/sweep, and the same episodes at 0.25 l in two other worlds, every contact's grip halved
# (ROBOT_DIR/sweep_grip_half) and the trunk 10% heavier (ROBOT_DIR/sweep_trunk_heavier); then the run's records
# (metrics.csv.xz; last.pt as a record checkpoint, no optimizer state, for every recipe but issue 46's frozen
# legged_trot; results/README.md).
# XML: a path, or a shipped model (menagerie/<robot>/scene.xml).
#   make robot RECIPE=legged_trot_v2 XML=menagerie/unitree_a1/scene.xml SEED=12 SWEEP_SEED=<s> ROBOT_DIR=<dir>
RECIPE ?= legged_trot
HEIGHTS ?= 0,0.2l,0.25l,0.3l
EPISODES ?= 100
robot: $(STAMP)
	@test -n "$(XML)" -a -n "$(SEED)" -a -n "$(ROBOT_DIR)" -a -n "$(SWEEP_SEED)" || { echo "error: make robot \
	needs XML=<model file> SEED=<training seed> ROBOT_DIR=<run dir> SWEEP_SEED=<episode seed>" >&2; exit 2; }
	$(call stage,$(ROBOT_DIR),experiment=$(RECIPE) env.xml_file=$(XML) seed=$(SEED) logger=csv $(ARGS))
	$(PY) -m ppo_torchrl.evaluate run=$(ROBOT_DIR) checkpoint=last episodes=$(EPISODES) seed=$(SWEEP_SEED) \
		heights=$(HEIGHTS) out=$(ROBOT_DIR)/sweep
	$(PY) -m ppo_torchrl.evaluate run=$(ROBOT_DIR) checkpoint=last episodes=$(EPISODES) seed=$(SWEEP_SEED) \
		heights=0.25l env.legged.friction_scale=0.5 out=$(ROBOT_DIR)/sweep_grip_half
	$(PY) -m ppo_torchrl.evaluate run=$(ROBOT_DIR) checkpoint=last episodes=$(EPISODES) seed=$(SWEEP_SEED) \
		heights=0.25l env.legged.trunk_mass_scale=1.1 out=$(ROBOT_DIR)/sweep_trunk_heavier
	$(PY) -m ppo_torchrl.records $(ROBOT_DIR)/metrics.csv $(foreach d,sweep sweep_grip_half sweep_trunk_heavier,\
		$(ROBOT_DIR)/$(d)/height_sweep.json $(ROBOT_DIR)/$(d)/height_sweep_episodes.csv) \
		$(if $(filter-out legged_trot,$(RECIPE)),$(ROBOT_DIR)/checkpoints/last.pt)

# stage(run dir, overrides): start the run there, resume it when a run there stopped, skip it when it finished.
# A run committed mid-way to results/ holds metrics.csv.xz only: its metrics.csv comes back before the resume.
stage = if grep -qs '"status": "finished"' $(1)/summary.json; then echo "$(1): finished"; \
	elif [ -d $(1) ]; then { [ -f $(1)/metrics.csv ] || [ ! -f $(1)/metrics.csv.xz ] || xz -dk $(1)/metrics.csv.xz; } && \
		MUJOCO_GL=egl $(PY) -m ppo_torchrl resume=$(1); \
	else MUJOCO_GL=egl $(PY) -m ppo_torchrl $(2) hydra.run.dir=$(1); fi

bench: $(STAMP)
	$(PY) -m pip install --quiet -e ".[bench]"
	$(PY) benchmarks/speed.py $(ARGS)

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache
