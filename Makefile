# The two commands README promises: `make test` and `make demo`. Both create .venv when missing and
# install the package with every dependency pinned (constraints.txt) from the package registries.
VENV ?= .venv
PYTHON ?= python3
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
OUT ?= out

# All ROS traffic stays on this host unless the caller says otherwise.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST

.PHONY: test demo lint bench install constraints clean

install: $(STAMP)

$(STAMP): requirements.txt constraints.txt setup.py package.xml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check \
		-c constraints.txt -r requirements.txt -e '.[test]'
	touch $@

lint: $(STAMP)
	$(BIN)/ruff check .

test: lint
	$(BIN)/python -m pytest test

demo: $(STAMP)
	mkdir -p $(OUT)
	$(BIN)/micro-feeder contact --plot $(OUT)/contact.png

bench: $(STAMP)
	for b in bench/bench_*.py; do $(BIN)/python $$b || exit 1; done

# Re-pin after changing requirements: freeze a fresh venv, drop the ROS wheels' bare names.
constraints:
	rm -rf /tmp/mf-constraints-venv && $(PYTHON) -m venv /tmp/mf-constraints-venv
	/tmp/mf-constraints-venv/bin/pip install --quiet -r requirements.txt -e '.[test]'
	/tmp/mf-constraints-venv/bin/pip freeze --exclude-editable | $(PYTHON) tools/pin_constraints.py > constraints.txt

clean:
	rm -rf $(VENV) $(OUT) build *.egg-info
