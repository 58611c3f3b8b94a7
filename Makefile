# One-command entry points. `make reproduce` builds everything; `make test` runs the suite.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
PROFILE ?= default

.PHONY: venv browser reproduce test cluster-test lint dry-run mlflow mlflow-sync report rulegraph run-time readme-results clean

$(BIN)/snakemake: pyproject.toml envs/constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -c envs/constraints.txt -e ".[test]"
	touch $@

venv: $(BIN)/snakemake

## Build the embedded world, prepare the data and every table that exists (PROFILE=tiny|default|paper)
reproduce: venv
	$(BIN)/snakemake all --config profile=$(PROFILE)

## Headless Chromium for tests/test_mlflow_ui.py: apt-get installs it where it is missing and we are root;
## elsewhere that one test skips (install chromium yourself, or set REDSUP_CHROMIUM to a Chrome binary)
browser:
	@command -v chromium >/dev/null 2>&1 || command -v chromium-browser >/dev/null 2>&1 || \
	  { [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1 && apt-get update -qq && \
	    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium; } || \
	  echo "make browser: no Chromium; tests/test_mlflow_ui.py will skip" >&2

## The test suite (what CI runs: .ci/run)
test: venv browser
	$(BIN)/python -m pytest tests --durations=15

## The SLURM profile on a one-node SLURM cluster started here (docs/cluster.md; CI runs it after `test`): as root
## it installs slurm-wlm and munge where missing; elsewhere the test skips
cluster-test: venv
	$(BIN)/pip install --quiet -c envs/constraints.txt -e ".[cluster]"
	REDSUP_SLURM_TEST=1 $(BIN)/python -m pytest tests/cluster -m slurm -s --durations=5

lint: venv
	$(BIN)/snakemake --lint

dry-run: venv
	$(BIN)/snakemake -n all

## Browse every run: http://127.0.0.1:5000
mlflow: venv
	$(BIN)/mlflow server --backend-store-uri sqlite:///results/mlflow.db --host 127.0.0.1 --port 5000

## Import every run record (results/runs/) into the MLflow store now, e.g. from a second shell mid-run
mlflow-sync: venv
	$(BIN)/python -m redsup.tracking

## Every table and figure with the thesis' caption and our verdict, in one HTML file (after `make reproduce`)
report: venv
	$(BIN)/snakemake --config profile=$(PROFILE) --report results/report.html

## The rules and how they depend on each other (needs Graphviz `dot`)
rulegraph: venv
	$(BIN)/snakemake --rulegraph --config profile=$(PROFILE) | dot -Tpng > docs/rulegraph.png

## Wall time and peak memory per rule and stage of the last run: results/tables/run_time.md
run-time: venv
	$(BIN)/snakemake run_time --config profile=$(PROFILE)

## The README's results block (between <!-- results:start --> and <!-- results:end -->) from the last build's
## results/tables/scorecard.md (after `make reproduce`)
readme-results: venv
	$(BIN)/python -m redsup.readme results --scorecard results/tables/scorecard.md --runs results/runs --readme README.md

clean:
	rm -rf results/* .snakemake
