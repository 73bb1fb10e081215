# The two commands of the README: `make demo` and `make check`.
# Both install missing Debian packages first, then configure and build.
BUILD ?= build
JOBS ?= $(shell nproc)
# Unity batches: a clean build (CI's) compiles in about 30% less time. For day-to-day
# work on a few files, a tree of its own with -DCMAKE_UNITY_BUILD=OFF rebuilds less per edit.
CMAKE_FLAGS ?= -DCMAKE_BUILD_TYPE=Release -DCMAKE_UNITY_BUILD=ON

.PHONY: all deps build demo check check-asan fuzz benches bench bench-service bench-direct bench-glossy bench-stability bench-soak bench-soak-attack bench-stream bench-lightfield bench-implicit accuracy accuracy-real images format clean

all: build

deps:
	@scripts/install-deps.sh

$(BUILD)/CMakeCache.txt: | deps
	cmake -S . -B $(BUILD) $(CMAKE_FLAGS)

build: deps $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

demo: build
	@scripts/demo.sh $(BUILD)

# Every test; then each fuzz target for CHECK_FUZZ_SECONDS (scripts/fuzz.sh); then the tests
# again with ASan and UBSan, but for the slowest (scripts/check-asan.sh --quick lists them).
CHECK_FUZZ_SECONDS ?= 10
check: build
	cd $(BUILD) && ctest --output-on-failure -j $(JOBS)
	FUZZ_SECONDS=$(CHECK_FUZZ_SECONDS) FUZZ_SEED=1 JOBS=$(JOBS) scripts/fuzz.sh
	JOBS=$(JOBS) scripts/check-asan.sh --quick

# The tests built with ASan and UBSan (scripts/check-asan.sh lists the ones left out, and why).
check-asan: deps
	@scripts/check-asan.sh

# libFuzzer targets with ASan and UBSan (scripts/fuzz.sh): FUZZ_SECONDS each (default 60).
fuzz: deps
	@scripts/fuzz.sh

# The benchmarks are not in the default build (bench/CMakeLists.txt): every rule below builds them.
benches: build
	cmake --build $(BUILD) -j $(JOBS) --target penumbra_benches

bench: benches
	$(BUILD)/bench/penumbra-bench-office --out bench/results

bench-service: benches
	$(BUILD)/bench/penumbra-bench-service --out bench/results

bench-lightfield: benches
	$(BUILD)/bench/penumbra-bench-lightfield --out bench/results

bench-implicit: benches
	$(BUILD)/bench/penumbra-bench-implicit --out bench/results
	$(BUILD)/bench/penumbra-bench-implicit --out bench/results --bin-cover closest --link-threshold 1

bench-direct: benches
	$(BUILD)/bench/penumbra-bench-direct --out bench/results

bench-glossy: benches
	$(BUILD)/bench/penumbra-bench-glossy --out bench/results

bench-stability: benches
	$(BUILD)/bench/penumbra-bench-stability --devices cpu,lavapipe --out bench/results

# A live server for SOAK_SECONDS (default 10 minutes) under 64 subscribers, 4 editors, a
# subscriber SIGKILLed every 30 s, one that stops reading and one sending garbage.
SOAK_SECONDS ?= 600
bench-soak: benches
	$(BUILD)/bench/penumbra-bench-soak --seconds $(SOAK_SECONDS) --out bench/results

# Bytes on the wire per frame encoding (f32, f16, delta streams) for the office and the
# Cornell box: a light slider, moves, idle; 64 delta subscribers (bench/results/stream.json).
bench-stream: benches
	$(BUILD)/bench/penumbra-bench-stream --out bench/results

# The soak without issue 63's attackers and with them (silent and slow connections, loaders
# that leave, a foreign reload), SOAK_ATTACK_SECONDS each: the legitimate clients' ratios.
SOAK_ATTACK_SECONDS ?= 60
SOAK_ATTACK_PAIRS ?= 3
bench-soak-attack: benches
	$(BUILD)/bench/penumbra-bench-soak --compare --pairs $(SOAK_ATTACK_PAIRS) --seconds $(SOAK_ATTACK_SECONDS) --name soak-attack --out bench/results

# The real-world corpus (scripts/real-corpus.sh): Debian's assimp-testmodels (installed when
# missing) and generated face-node and sunlit scenes, each solver at the defaults against the
# reference; bench/results/real-corpus.md.
accuracy-real: build
	scripts/real-corpus.sh $(BUILD) bench/results

accuracy: benches
	$(BUILD)/bench/penumbra-bench-accuracy --out bench/results

# The pictures of docs/BAKING.md: the Cornell box and the office lit by the solver alone and with the
# gather stage (bake's defaults, shaded per input vertex), the path-traced reference, and
# each answer's error against it as a heat map; each answer's `compare` against the reference
# goes to bench/results/images.json.
OFFICE_CAMERA = 0.6,2.2,0.6,8,0.6,6,75
images: build
	@mkdir -p docs/images
	$(BUILD)/penumbra reference scenes/cornell-box.gltf -o $(BUILD)/cornell-reference.json --samples 4096 -q
	$(BUILD)/penumbra bake scenes/cornell-box.gltf -o $(BUILD)/cornell-alone.json --gather off --direct-rays 0 -q
	$(BUILD)/penumbra bake scenes/cornell-box.gltf -o $(BUILD)/cornell-gather.json -q
	$(BUILD)/penumbra render scenes/cornell-box.gltf --lighting $(BUILD)/cornell-reference.json -o docs/images/cornell-box-reference.png --size 512x512
	$(BUILD)/penumbra render scenes/cornell-box.gltf --lighting $(BUILD)/cornell-alone.json -o docs/images/cornell-box-alone.png --size 512x512
	$(BUILD)/penumbra render scenes/cornell-box.gltf --lighting $(BUILD)/cornell-gather.json -o docs/images/cornell-box.png --size 512x512
	$(BUILD)/penumbra render scenes/cornell-box.gltf --lighting $(BUILD)/cornell-alone.json --compare $(BUILD)/cornell-reference.json -o docs/images/cornell-box-alone-error.png --size 512x512 --error-scale 0.5
	$(BUILD)/penumbra render scenes/cornell-box.gltf --lighting $(BUILD)/cornell-gather.json --compare $(BUILD)/cornell-reference.json -o docs/images/cornell-box-error.png --size 512x512 --error-scale 0.5
	$(BUILD)/penumbra reference scenes/office.gltf -o $(BUILD)/office-reference.json --samples 4096 -q
	$(BUILD)/penumbra bake scenes/office.gltf -o $(BUILD)/office-alone.json --gather off --direct-rays 0 -q
	$(BUILD)/penumbra bake scenes/office.gltf -o $(BUILD)/office-gather.json -q
	$(BUILD)/penumbra render scenes/office.gltf --camera $(OFFICE_CAMERA) --lighting $(BUILD)/office-reference.json -o docs/images/office-reference.png --size 640x400
	$(BUILD)/penumbra render scenes/office.gltf --camera $(OFFICE_CAMERA) --lighting $(BUILD)/office-alone.json -o docs/images/office-alone.png --size 640x400
	$(BUILD)/penumbra render scenes/office.gltf --camera $(OFFICE_CAMERA) --lighting $(BUILD)/office-gather.json -o docs/images/office.png --size 640x400
	$(BUILD)/penumbra render scenes/office.gltf --camera $(OFFICE_CAMERA) --lighting $(BUILD)/office-alone.json --compare $(BUILD)/office-reference.json -o docs/images/office-alone-error.png --size 640x400 --error-scale 0.5
	$(BUILD)/penumbra render scenes/office.gltf --camera $(OFFICE_CAMERA) --lighting $(BUILD)/office-gather.json --compare $(BUILD)/office-reference.json -o docs/images/office-error.png --size 640x400 --error-scale 0.5
	@{ printf '{"date": "%s", "machine": "%s, %s cores (CPU back end)", "reference": "penumbra reference --samples 4096", "compare": {' \
	     "$$(date -u +%F)" "$$(uname -m)" "$$(nproc)"; sep=''; \
	   for a in cornell-alone cornell-gather office-alone office-gather; do \
	     printf '%s"%s": ' "$$sep" "$$a"; sep=', '; \
	     $(BUILD)/penumbra compare --json $(BUILD)/$$a.json $(BUILD)/$${a%%-*}-reference.json; \
	   done; echo '}}'; } > bench/results/images.json
	@echo "wrote bench/results/images.json"
	$(BUILD)/penumbra render scenes/glossy-box.gltf -o docs/images/glossy-box.png --size 512x384 --channel total --solver antiradiance --bins 256 --element-size 0.08 --iterations 8
	$(BUILD)/penumbra reference scenes/glossy-box.gltf -o $(BUILD)/glossy-reference.json --channel total --samples 4096 -q
	$(BUILD)/penumbra render scenes/glossy-box.gltf --lighting $(BUILD)/glossy-reference.json -o docs/images/glossy-box-reference.png --size 512x384

format:
	clang-format -i $$(git ls-files '*.cpp' '*.h' '*.hpp')

clean:
	rm -rf $(BUILD)
