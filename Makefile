# ssm_localization developer entry points. Every target sets itself up from a fresh clone.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed-stamp
OUT    := out
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export MPLBACKEND ?= Agg
# one BLAS thread unless set (as the console scripts do; see ssm_localization/threads.py)
export OPENBLAS_NUM_THREADS ?= 1
export OMP_NUM_THREADS ?= 1
export MKL_NUM_THREADS ?= 1

.PHONY: venv demo test test-fast lint params-yaml bench bench-scanmatch bench-index bench-localize bench-track colcon-check clean

$(STAMP): requirements.txt setup.py setup.cfg
	@$(PYTHON) -c 'import sys; assert sys.version_info >= (3, 10), "Python 3.10+ required"'
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -r requirements.txt
	$(BIN)/python -m pip install --quiet --no-deps --no-build-isolation -e .
	touch $(STAMP)

venv: $(STAMP)

demo: $(STAMP)
	@mkdir -p $(OUT)
	$(BIN)/python -m ssm_localization.demo --out $(OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -q -ra

# test/unit without DDS (under a minute); make test runs test/unit and test/integration
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -ra test/unit -m "not slow and not dds and not linter"

lint: $(STAMP)
	$(BIN)/python -m pytest -q -ra test -m linter

bench: bench-scanmatch bench-index bench-localize bench-track

bench-scanmatch: $(STAMP)
	$(BIN)/ssm_localization bench scanmatch

bench-index: $(STAMP)
	$(BIN)/ssm_localization bench index

bench-localize: $(STAMP)
	$(BIN)/ssm_localization bench localize

bench-track: $(STAMP)
	$(BIN)/ssm_localization bench track

colcon-check: $(STAMP)
	rm -rf build/colcon install/colcon log/colcon
	$(BIN)/colcon --log-base log/colcon build --build-base build/colcon --install-base install/colcon \
		--paths . --packages-select ssm_localization
	test -x install/colcon/ssm_localization/lib/ssm_localization/global_localizer
	test -f install/colcon/ssm_localization/share/ament_index/resource_index/packages/ssm_localization

params-yaml: $(STAMP)
	$(BIN)/python -m ssm_localization.ros.parameters config/ssm_localization.yaml docs/PARAMETERS.md

clean:
	rm -rf $(VENV) build install log $(OUT) *.egg-info
