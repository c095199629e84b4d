# The two commands README promises: `make test` and `make demo`. Both create .venv when missing and
# install the package with every dependency pinned (constraints.txt) from the package registries.
VENV ?= .venv
PYTHON ?= python3
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
INTERFACES := $(VENV)/.interfaces
INTERFACE_PACKAGES := control_msgs simulation_interfaces
INTERFACE_SOURCES := $(shell find interfaces -type f)
OUT ?= out

# All ROS traffic stays on this host unless the caller says otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: test demo lint bench install constraints clean foxglove-client figures performance-doc

install: $(STAMP) $(INTERFACES)

$(STAMP): requirements.txt constraints.txt setup.py package.xml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check \
		-c constraints.txt -r requirements.txt -e '.[test]'
	touch $@

# The standard interface packages that are not on the index (interfaces/: simulation_interfaces 2.0.0,
# control_msgs' FollowJointTrajectory), generated with rosidl into the venv; rebuilt only when their sources,
# the script or the venv's packages change (needs cmake and a C/C++ compiler; ~35 s, README).
$(INTERFACES): $(STAMP) $(INTERFACE_SOURCES) tools/build_interfaces.sh
	tools/build_interfaces.sh $(VENV) $(VENV)/interfaces-build $(INTERFACE_PACKAGES)
	touch $@

lint: $(STAMP) $(INTERFACES)
	$(BIN)/ruff check .
	$(BIN)/lint-imports --no-cache

test: lint foxglove-client $(INTERFACES)
	$(BIN)/python -m pytest test -m 'not paths and not fresh_cache'

# The real Foxglove WebSocket client the live-view tests use (npm, pinned by package-lock.json; node >= 18).
FOXGLOVE_CLIENT := test/foxglove_client
foxglove-client: $(FOXGLOVE_CLIENT)/node_modules/.installed

$(FOXGLOVE_CLIENT)/node_modules/.installed: $(FOXGLOVE_CLIENT)/package.json $(FOXGLOVE_CLIENT)/package-lock.json
	cd $(FOXGLOVE_CLIENT) && npm ci --ignore-scripts --no-audit --no-fund
	touch $@

# The whole pipeline: contact model, an offline stroke and a frequency sweep, the ROS nodes recording a
# run, a look at the log, its re-simulation, and the feed controller in the loop.
demo: $(STAMP) $(INTERFACES)
	rm -rf $(OUT)/run && mkdir -p $(OUT)
	$(BIN)/micro-feeder contact --plot $(OUT)/contact.png
	$(BIN)/micro-feeder simulate --out $(OUT) --plot $(OUT)/simulate.png
	$(BIN)/micro-feeder sweep --vary stroke.frequency=100:5000:200 --set stroke.count=5 --out $(OUT) --plot $(OUT)/sweep.png
	$(BIN)/micro-feeder run --duration 3 --set stroke.count=5 --record $(OUT)/run
	$(BIN)/micro-feeder info $(OUT)/run
	$(BIN)/micro-feeder plot $(OUT)/run -o $(OUT)/run.png
	$(BIN)/micro-feeder resim $(OUT)/run
	$(BIN)/micro-feeder hil --lockstep --params config/travelling_wave.yaml --set feed.target_x=0.8e-3

# The figures README and docs/ show (docs/img), regenerated from the commands that make them.
IMG := docs/img
FIG_OUT := $(OUT)/figures
figures: $(STAMP)
	rm -rf $(FIG_OUT) && mkdir -p $(FIG_OUT)
	$(BIN)/micro-feeder contact --plot $(IMG)/contact.png
	$(BIN)/micro-feeder simulate --out $(FIG_OUT) --plot $(IMG)/simulate_default.png
	$(BIN)/micro-feeder simulate --out $(FIG_OUT) --set stroke.frequency=3000 --duration 0.3 --plot $(IMG)/simulate_takeoff.png
	$(BIN)/micro-feeder simulate --out $(FIG_OUT) --params config/travelling_wave.yaml --plot $(IMG)/simulate_travelling_wave.png
	$(BIN)/micro-feeder sweep --vary stroke.frequency=100:5000:200 --set stroke.count=5 --out $(FIG_OUT) --plot $(IMG)/sweep_frequency.png
	$(BIN)/micro-feeder sweep --params config/travelling_wave.yaml --set stroke.count=40 \
		--set 'particle.x0=[0.4e-3,0.55e-3,0.7e-3,0.85e-3,1.0e-3,1.15e-3,1.3e-3,1.45e-3]' --gate 0.9e-3 \
		--vary stroke.amplitude=60e-6:200e-6:15 --out $(FIG_OUT) --plot $(IMG)/sweep_parts_collisions.png --quantity collisions
	$(BIN)/micro-feeder run --duration 0.1 --set stroke.count=5 --real-time-factor 0.05 --record $(FIG_OUT)/run
	$(BIN)/micro-feeder plot $(FIG_OUT)/run -o $(IMG)/run.png
	$(BIN)/python docs/img/track_landing_laws.py $(IMG)/track_landing_laws.png
	$(BIN)/python docs/img/travelling_wave_thickness.py $(IMG)/travelling_wave_thickness.png
	$(BIN)/micro-feeder sweep --set surface.kind=track --set contact.model=coulomb --set landing.law=coulomb --set stroke.waveform=sine --set stroke.count=30 --vary stroke.frequency=50:300:26 --vary stroke.amplitude=10e-6:150e-6:29 --out $(FIG_OUT) --plot $(IMG)/track_map.png
	$(BIN)/python $(IMG)/nodes_topics.py $(IMG)/nodes_topics.png

bench: $(STAMP) $(INTERFACES) foxglove-client
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -r bench/requirements-dem.txt
	for b in bench/bench_*.py; do $(BIN)/python $$b || exit 1; done

# docs/performance.md and README's table of figures, from what the benchmarks wrote to bench/results/*.json.
performance-doc: $(STAMP)
	$(BIN)/python bench/report.py

# Re-pin after changing requirements: freeze a fresh venv, drop the ROS wheels' bare names.
constraints:
	rm -rf /tmp/mf-constraints-venv && $(PYTHON) -m venv /tmp/mf-constraints-venv
	/tmp/mf-constraints-venv/bin/pip install --quiet -r requirements.txt -e '.[test]'
	/tmp/mf-constraints-venv/bin/pip freeze --exclude-editable | $(PYTHON) tools/pin_constraints.py > constraints.txt

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info $(FOXGLOVE_CLIENT)/node_modules
