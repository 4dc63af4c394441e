# weft: the commands a developer runs. `make demo` and `make test` work on a fresh Debian 12
# machine (they install what is missing first).
BUILD   ?= build
VENV    ?= .venv
PY      := $(VENV)/bin/python
JOBS    ?= $(shell nproc)
GEN     := $(shell command -v ninja >/dev/null 2>&1 && echo -G Ninja)
# ccache when present (rebuilds of other checkouts of the tree reuse objects).
LAUNCHER := $(shell command -v ccache >/dev/null 2>&1 && echo -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)

.PHONY: all deps build proto-py demo test test-engine test-python bench clean

all: build

deps:
	./scripts/install-deps

build: deps
	@[ -f $(BUILD)/CMakeCache.txt ] || cmake -S . -B $(BUILD) $(GEN) $(LAUNCHER) -DCMAKE_BUILD_TYPE=RelWithDebInfo
	cmake --build $(BUILD) -j $(JOBS)
	$(MAKE) --no-print-directory proto-py

# Python gRPC stubs, generated into the client package (clients/python/weft/v1, git-ignored).
proto-py:
	@mkdir -p clients/python/weft/v1
	$(PY) -m grpc_tools.protoc -Iproto --python_out=clients/python --grpc_python_out=clients/python proto/weft/v1/*.proto
	@touch clients/python/weft/v1/__init__.py

demo: build
	WEFT_DAEMON=$(CURDIR)/$(BUILD)/bin/weftd $(PY) clients/python/examples/demo.py

test: build
	$(MAKE) --no-print-directory test-engine test-python

test-engine:
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

test-python:
	WEFT_DAEMON=$(CURDIR)/$(BUILD)/bin/weftd $(PY) -m pytest -q clients/python/tests

bench: build
	$(PY) -m pip install -q warp-lang
	WEFT_DAEMON=$(CURDIR)/$(BUILD)/bin/weftd $(PY) bench/run_all.py

clean:
	rm -rf $(BUILD)
