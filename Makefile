# `make test` and `make run` work on a fresh machine with only python3, pip and gcc:
# they create .venv once and reuse it afterwards.
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

TS := clients/typescript
TS_STAMP := $(TS)/node_modules/.installed

CPP := clients/cpp
CPP_BUILD := build/cpp
# Debian's packages the C++ client builds with.
CPP_DEBS := libmsgpack-cxx-dev libcpp-httplib-dev nlohmann-json3-dev libboost-dev pkg-config
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: test test-quick test-ts test-cpp cpp-deps viewer browser-deps test-browser viewer-screenshot \
	run lint bench bench-quick clean cluster cluster-deps

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

# The browser tests (tests/test_viewer.py, marked browser) run in the suite: they need the
# built viewer and Debian's chromium.
test: $(STAMP) lint viewer browser-deps cluster-deps
	$(BIN)/python -m pytest -n 2 -q --durations=15
	$(MAKE) test-ts
	$(MAKE) test-cpp

# The TypeScript client (node 20+ and npm): its golden replay, the conformance suite and
# its service tests, against a `lightsched serve` the tests start from .venv.
$(TS_STAMP): $(TS)/package-lock.json
	cd $(TS) && npm ci --no-audit --no-fund
	touch $(TS_STAMP)

test-ts: $(STAMP) $(TS_STAMP)
	cd $(TS) && npm test

# The C++ client (C++17, CMake): its golden replay, the conformance suite and a live round
# trip, each against a `lightsched serve` the test starts from .venv.
cpp-deps:
	@dpkg -s $(CPP_DEBS) >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $(CPP_DEBS); }

test-cpp: $(STAMP) cpp-deps
	cmake -S $(CPP) -B $(CPP_BUILD) -DCMAKE_BUILD_TYPE=Release
	cmake --build $(CPP_BUILD) -j2
	ctest --test-dir $(CPP_BUILD) --output-on-failure

# The viewer page (/viewer): the TypeScript client's viewer/ bundled with three.js by esbuild
# into $(TS)/dist/viewer, which the service serves.
VIEWER := $(TS)/dist/viewer/main.js
$(VIEWER): $(TS_STAMP) $(wildcard $(TS)/src/*.ts $(TS)/viewer/*) $(TS)/tsconfig.viewer.json
	cd $(TS) && npm run viewer

viewer: $(VIEWER)

# Debian's chromium, which Playwright (its Python package, a dev extra) drives for the
# browser tests; Playwright's own browser download is never used (nothing outside the
# package registries can be fetched here).
BROWSER_DEBS := chromium
browser-deps:
	@dpkg -s $(BROWSER_DEBS) >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $(BROWSER_DEBS); }

test-browser: $(STAMP) viewer browser-deps
	$(BIN)/python -m pytest -q -m browser tests/test_viewer.py

# The README's picture of the viewer, as the browser test takes it (docs/viewer.png).
viewer-screenshot: $(STAMP) viewer browser-deps
	LIGHTSCHED_VIEWER_SCREENSHOT=docs/viewer.png $(BIN)/python -m pytest -q -m browser tests/test_viewer.py

# ~3 minutes on 2 cores with numba's cache warm (the full suite takes ~20): a tenth of the
# hypothesis examples, and without the tests marked slow (those that compile or warm up
# every kernel in a child process). Every module still meets the oracle; `make test` is
# what CI runs.
test-quick: $(STAMP) lint cluster-deps
	LIGHTSCHED_EXAMPLES=10 $(BIN)/python -m pytest -n 2 -q -m "not slow and not browser" --durations=10

# The viewer is at http://127.0.0.1:8080/viewer. Its origin under either name of this
# machine may call the service (a page of localhost:8080 calling 127.0.0.1:8080 is
# cross-origin).
run: $(STAMP) viewer
	LIGHTSCHED_CORS_ORIGINS=$${LIGHTSCHED_CORS_ORIGINS-http://127.0.0.1:8080,http://localhost:8080} \
	$(BIN)/python -m lightsched serve --host 127.0.0.1 --port 8080

# Debian's haproxy, in front of the workers of `make cluster` and of the cluster tests
# (tests/test_cluster.py), which the suite runs: they need it.
CLUSTER_DEBS := haproxy
cluster-deps:
	@dpkg -s $(CLUSTER_DEBS) >/dev/null 2>&1 || { $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $(CLUSTER_DEBS); }

# HAProxy on 127.0.0.1:8080 (deploy/haproxy.cfg) in front of WORKERS `lightsched serve`
# processes, sessions routed by id; Ctrl-C stops them all.
WORKERS ?= 2
cluster: $(STAMP) cluster-deps
	$(BIN)/python -m lightsched_server.cluster --workers $(WORKERS) --port 8080

# Every benchmark, each writing its section of bench/RESULTS.md and its plots.
bench: $(STAMP)
	$(BIN)/python bench/run_all.py

# The ~2-minute cut of the same.
bench-quick: $(STAMP)
	$(BIN)/python bench/run_all.py --quick

clean:
	rm -rf $(VENV) build *.egg-info $(TS)/node_modules $(TS)/dist $(CPP_BUILD)
