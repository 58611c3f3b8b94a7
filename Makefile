# One-command entry points. `make reproduce` builds everything; `make test` runs the suite.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
PROFILE ?= default

.PHONY: venv reproduce test lint dry-run mlflow clean

$(BIN)/snakemake: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip
	$(BIN)/pip install --quiet -e ".[test]"
	touch $@

venv: $(BIN)/snakemake

## Build the embedded world, prepare the data and every table that exists (PROFILE=tiny|default|paper)
reproduce: venv
	$(BIN)/snakemake all --config profile=$(PROFILE)

## The test suite (what CI runs)
test: venv
	$(BIN)/python -m pytest tests

lint: venv
	$(BIN)/snakemake --lint

dry-run: venv
	$(BIN)/snakemake -n all

## Browse every run: http://127.0.0.1:5000
mlflow: venv
	$(BIN)/mlflow server --backend-store-uri sqlite:///results/mlflow.db --host 127.0.0.1 --port 5000

clean:
	rm -rf results/* .snakemake
