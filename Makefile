# The two commands of the README: `make demo` and `make check`.
# Both install missing Debian packages first, then configure and build.
BUILD ?= build
JOBS ?= $(shell nproc)
CMAKE_FLAGS ?= -DCMAKE_BUILD_TYPE=Release

.PHONY: all deps build demo check bench bench-service bench-direct accuracy format clean

all: build

deps:
	@scripts/install-deps.sh

$(BUILD)/CMakeCache.txt: | deps
	cmake -S . -B $(BUILD) $(CMAKE_FLAGS)

build: deps $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

demo: build
	@scripts/demo.sh $(BUILD)

check: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)

bench: build
	$(BUILD)/bench/penumbra-bench-office --out bench/results

bench-service: build
	$(BUILD)/bench/penumbra-bench-service --out bench/results

bench-direct: build
	$(BUILD)/bench/penumbra-bench-direct --out bench/results

accuracy: build
	$(BUILD)/bench/penumbra-bench-accuracy --out bench/results

format:
	clang-format -i $$(git ls-files '*.cpp' '*.h' '*.hpp')

clean:
	rm -rf $(BUILD)
