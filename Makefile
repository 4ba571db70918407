# `make test` and `make run` work on a fresh machine with only python3, pip and gcc:
# they create .venv once and reuse it afterwards.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

TS := clients/typescript
TS_STAMP := $(TS)/node_modules/.installed

.PHONY: test test-quick test-ts run lint bench bench-quick clean

# The root distribution ships lightsched_client too (the server's wire codec): a venv made
# before it did has the client's own distribution as well, which is dropped so that only one
# distribution owns the package.
$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(BIN)/python -m pip install --upgrade pip
	$(BIN)/python -m pip uninstall -y -q lightsched-client
	$(BIN)/python -m pip install -e '.[dev]'
	touch $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check .

test: $(STAMP) lint
	$(BIN)/python -m pytest -n 2 -q --durations=15
	$(MAKE) test-ts

# The TypeScript client (node 20+ and npm): its golden replay, the conformance suite and
# its service tests, against a `lightsched serve` the tests start from .venv.
$(TS_STAMP): $(TS)/package-lock.json
	cd $(TS) && npm ci --no-audit --no-fund
	touch $(TS_STAMP)

test-ts: $(STAMP) $(TS_STAMP)
	cd $(TS) && npm test

# ~3 minutes on 2 cores with numba's cache warm (the full suite takes ~20): a tenth of the
# hypothesis examples, and without the tests marked slow (those that compile or warm up
# every kernel in a child process). Every module still meets the oracle; `make test` is
# what CI runs.
test-quick: $(STAMP) lint
	LIGHTSCHED_EXAMPLES=10 $(BIN)/python -m pytest -n 2 -q -m "not slow" --durations=10

# The viewer's origin under either name of this machine may call the service (a page of
# localhost:8080 calling 127.0.0.1:8080 is cross-origin).
run: $(STAMP)
	LIGHTSCHED_CORS_ORIGINS=$${LIGHTSCHED_CORS_ORIGINS-http://127.0.0.1:8080,http://localhost:8080} \
	$(BIN)/python -m lightsched serve --host 127.0.0.1 --port 8080

# Every benchmark, each writing its section of bench/RESULTS.md and its plots.
bench: $(STAMP)
	$(BIN)/python bench/run_all.py

# The ~2-minute cut of the same.
bench-quick: $(STAMP)
	$(BIN)/python bench/run_all.py --quick

clean:
	rm -rf $(VENV) build *.egg-info $(TS)/node_modules $(TS)/dist
