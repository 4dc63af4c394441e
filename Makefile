# weft: the commands a developer runs. `make demo` and `make test` work on a fresh Debian 12
# machine (they install what is missing first).
BUILD   ?= build
VENV    ?= .venv
PY      := $(VENV)/bin/python
JOBS    ?= $(shell nproc)
GEN     := $(shell command -v ninja >/dev/null 2>&1 && echo -G Ninja)
# ccache when present (rebuilds of other checkouts of the tree reuse objects).
LAUNCHER := $(shell command -v ccache >/dev/null 2>&1 && echo -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)

# Sanitizer + fuzzing build (clang-19, ASan + UBSan, libFuzzer targets): docs/testing.md.
ASAN_BUILD   ?= build-asan
FUZZ_SECONDS ?= 25
SAN_SUPP     := $(CURDIR)/tests/sanitizers
ASAN_OPTS    := detect_leaks=1:detect_stack_use_after_return=1
SAN_OTHER    := LSAN_OPTIONS=suppressions=$(SAN_SUPP)/lsan.supp:print_suppressions=0 \
                UBSAN_OPTIONS=print_stacktrace=1:suppressions=$(SAN_SUPP)/ubsan.supp
SAN_ENV      := ASAN_OPTIONS=$(ASAN_OPTS) $(SAN_OTHER)

.PHONY: all deps build proto-py demo test test-engine test-python bench clean \
        asan-configure build-asan fuzz-build test-fuzz fuzz-long test-asan

all: build

deps:
	./scripts/install-deps

build: deps
	@[ -f $(BUILD)/CMakeCache.txt ] || cmake -S . -B $(BUILD) $(GEN) $(LAUNCHER) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DPython3_EXECUTABLE=$(CURDIR)/$(PY)
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
	$(MAKE) --no-print-directory test-engine test-python test-fuzz

test-engine:
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

test-python:
	WEFT_DAEMON=$(CURDIR)/$(BUILD)/bin/weftd $(PY) -m pytest -q clients/python/tests

asan-configure: deps
	@[ -f $(ASAN_BUILD)/CMakeCache.txt ] || CC=clang-19 CXX=clang++-19 cmake -S . -B $(ASAN_BUILD) $(GEN) \
	  $(LAUNCHER) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DWEFT_SANITIZE=ON -DWEFT_FUZZ=ON

# Only the fuzz targets (what `make test` needs); build-asan builds everything.
fuzz-build: asan-configure
	cmake --build $(ASAN_BUILD) -j $(JOBS) --target weft_fuzz_compile weft_fuzz_api weft_fuzz_artifact

build-asan: asan-configure
	cmake --build $(ASAN_BUILD) -j $(JOBS)

# A short run of every fuzz target from its committed corpus; fails on any crash or report.
test-fuzz: fuzz-build
	$(SAN_ENV) scripts/fuzz $(ASAN_BUILD) compile $(FUZZ_SECONDS)
	$(SAN_ENV) scripts/fuzz $(ASAN_BUILD) api $(FUZZ_SECONDS)
	$(SAN_ENV) scripts/fuzz $(ASAN_BUILD) artifact $(FUZZ_SECONDS)

# The long run (FUZZ_TARGET=compile|api|artifact, FUZZ_LONG_SECONDS): corpus grows in out/fuzz/.
fuzz-long: fuzz-build
	$(SAN_ENV) scripts/fuzz $(ASAN_BUILD) $(or $(FUZZ_TARGET),compile) $(or $(FUZZ_LONG_SECONDS),3600)

# The whole suite against the ASan/UBSan build: engine GoogleTest, then pytest end-to-end
# against an instrumented weftd (its reports go to $(ASAN_BUILD)/sanitizer-logs, checked last).
test-asan: build-asan proto-py
	rm -rf $(ASAN_BUILD)/sanitizer-logs && mkdir -p $(ASAN_BUILD)/sanitizer-logs
	$(SAN_ENV) ctest --test-dir $(ASAN_BUILD) --output-on-failure -j $(JOBS)
	ASAN_OPTIONS=$(ASAN_OPTS):log_path=$(CURDIR)/$(ASAN_BUILD)/sanitizer-logs/weftd $(SAN_OTHER) \
	  WEFT_DAEMON=$(CURDIR)/$(ASAN_BUILD)/bin/weftd $(PY) -m pytest -q clients/python/tests
	scripts/check-sanitizer-logs $(ASAN_BUILD)/sanitizer-logs

bench: build
	$(PY) -m pip install -q warp-lang
	WEFT_DAEMON=$(CURDIR)/$(BUILD)/bin/weftd $(PY) bench/run_all.py

clean:
	rm -rf $(BUILD)
