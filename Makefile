# The two commands of the quick start; each sets up what it needs from nothing.
#   make run    create .venv, install partcal, run the paper study on the shipped virtual-SK120 data
#   make test   create .venv, install partcal with its test tools, run the whole suite
# Both install exactly the versions of requirements.lock; make lock refreshes it (see its header).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
LOCK   := requirements.lock

SYSTEM := $(VENV)/.system-packages
# Debian packages the report tests use: the browser, and Mesa's EGL for off-screen 3-D pictures
DEBS   := chromium libegl1 libegl-mesa0 libgl1-mesa-dri

.PHONY: run test bench lock clean mutation

$(STAMP): pyproject.toml $(LOCK)
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet -c $(LOCK) pip
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[test]'
	touch $@

# The newest versions pyproject.toml allows, frozen: a throw-away venv, so .venv keeps what it tested
lock:
	rm -rf .venv-lock && $(PYTHON) -m venv .venv-lock
	.venv-lock/bin/python -m pip install --quiet --upgrade pip
	.venv-lock/bin/python -m pip install --quiet '.[test]'
	{ sed -n '/^#/p' $(LOCK); .venv-lock/bin/python -m pip freeze --all | grep -v '^partcal[ =@]'; } > $(LOCK).new
	mv $(LOCK).new $(LOCK) && rm -rf .venv-lock

$(SYSTEM):
	@missing=""; for p in $(DEBS); do dpkg -s $$p >/dev/null 2>&1 || missing="$$missing $$p"; done; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; \
	fi
	mkdir -p $(VENV) && touch $@

run: $(STAMP)
	$(BIN)/partcal run configs/paper_sk120.yaml

test: $(STAMP) $(SYSTEM)
	$(BIN)/python -m pytest -n 2

# pyswarms: the peer to beat (bench_swarm.py); numba: a compiled swarm loop, the bound that
# bench_swarm_batch.py measures. Neither is a dependency of partcal.
bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -c $(LOCK) pyswarms numba
	for b in benchmarks/bench_*.py; do $(BIN)/python $$b || exit 1; done

# Mutation testing of one module against the tests that guard it (CONTRIBUTING.md): slow, never in CI.
#   make mutation MODULE=partcal/study/check.py TESTS="tests/test_check.py"
# ONLY=explain,ALPHA: those definitions alone; RETEST=1: after new tests, the survivors again.
# cosmic-ray is a development tool only: pinned in pyproject.toml's extra 'mutation', installed beside the
# locked versions, never in the lock that make test installs.
mutation: $(STAMP)
	@test -n "$(MODULE)" -a -n "$(TESTS)" || { echo 'usage: make mutation MODULE=partcal/x.py TESTS="tests/test_x.py ..."'; exit 2; }
	$(BIN)/python -m pip install --quiet -c $(LOCK) -e '.[mutation]'
	$(BIN)/python tools/mutation.py $(MODULE) "$(TESTS)" $(if $(ONLY),--only $(ONLY)) $(if $(RETEST),--retest-survivors)

clean:
	rm -rf $(VENV) reports .pytest_cache .mutation
