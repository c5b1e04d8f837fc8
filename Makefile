# make run: set up .venv and run the demo (server + demo client, writes out/demo.mp4).
# make test: set up .venv, run scripts/check (ruff's lint and format check, mypy, the layout rules;
# configured in pyproject.toml) and the test suite.
PYTHON ?= python3.11
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
DEPS := pyproject.toml proto/pyproject.toml client_sdk/python/pyproject.toml scripts/system-deps.sh
# camdirector._native (native/, Rust; scripts/system-deps.sh wants cargo): the editable install
# compiles it into src/camdirector/, and again after an edit of the crate (cargo's cache in
# native/target keeps that quick).
NATIVE := native/Cargo.toml native/Cargo.lock $(shell find native/src -name '*.rs')
NATIVE_STAMP := $(VENV)/.native-stamp

.PHONY: run test proto bench dist clean

$(STAMP): $(DEPS)
	bash scripts/system-deps.sh
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e proto -e client_sdk/python -e '.[dev]'
	touch $(STAMP)

# order-only on $(STAMP): its install compiled the module already, so its rerun alone recompiles nothing
$(NATIVE_STAMP): $(NATIVE) | $(STAMP)
	$(BIN)/python -m pip install -q --no-deps -e .
	touch $(NATIVE_STAMP)

run: $(NATIVE_STAMP)
	$(BIN)/camdirector demo --out out

test: $(NATIVE_STAMP)
	bash scripts/system-deps.sh --tests
	BIN=$(BIN) bash scripts/check
	$(BIN)/python -m pytest

# Regenerates the committed wire-contract code after an edit of proto/camdirector/v1/*.proto.
proto: $(STAMP)
	$(BIN)/python -m grpc_tools.protoc -I proto --python_out=proto --pyi_out=proto \
		--grpc_python_out=proto proto/camdirector/v1/director.proto

bench: $(NATIVE_STAMP)
	$(BIN)/python -m load_tests.stream --transport grpc --sessions 1 --seconds 10 --json out/bench-grpc-1.json
	$(BIN)/python -m load_tests.stream --transport zmq --sessions 1 --seconds 10 --json out/bench-zmq-1.json

# The release artifacts, named with the version: wheels and sdists, the C/C++ SDK's install tree,
# the service image (scripts/dist.sh; tests/test_dist.py checks what it makes).
dist: $(STAMP)
	rm -rf dist
	PYTHON=$(BIN)/python bash scripts/dist.sh dist

clean:
	rm -rf $(VENV) out dist
