# Two commands for a fresh checkout: `make train` and `make test`. Both create .venv when missing.
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: setup train test bench clean

setup: $(STAMP)

# The CPU wheel of torch first and pinned: an unpinned torch would pull several GB of CUDA packages.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet torch==2.13.0
	$(PY) -m pip install --quiet -e ".[test,loggers,sweeps]"
	touch $(STAMP)

train: $(STAMP)
	MUJOCO_GL=egl $(PY) -m ppo_torchrl env=Hopper-v4 $(ARGS)

# pytest exits 5 when it collects nothing; that is a failure here, never a silent pass.
# -n 2: two test processes (pytest-xdist), one per core of the 2-core CI machine.
test: $(STAMP)
	$(PY) -m pytest -q -n 2 $(ARGS)

bench: $(STAMP)
	$(PY) -m pip install --quiet -e ".[bench]"
	$(PY) benchmarks/speed.py $(ARGS)

clean:
	rm -rf $(VENV) outputs multirun .pytest_cache
