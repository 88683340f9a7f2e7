# The two commands a new user needs (see README.md):
#   make run    install, build, and serve the demo DEM on http://127.0.0.1:8080/
#   make test   install, build, and run every test
# Also: make build, make bench, make fuzz, make format.

JOBS ?= $(shell nproc)
PORT ?= 8080
HOST ?= 127.0.0.1

.PHONY: setup build build-test run test bench fuzz format clean

setup:
	scripts/setup.sh

build: setup
	cmake -S . -B build -DCMAKE_BUILD_TYPE=Release -DTB_BUILD_TESTS=OFF
	cmake --build build -j $(JOBS) --target terrabound

run: build
	./build/terrabound serve config/demo.json --host $(HOST) --port $(PORT)

# Tests build with assertions live (no NDEBUG) but optimized, so the property sweeps stay quick.
build-test: setup
	cmake -S . -B build-test -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-g -O2" \
	    -DTB_BUILD_TESTS=ON -DTB_WERROR=ON
	cmake --build build-test -j $(JOBS)

test: build-test
	cd build-test && ctest --output-on-failure --timeout 1500

bench: setup
	bench/mesh_bench.sh

# libFuzzer harnesses (clang, ASan) for FUZZ_SECONDS each; see tests/fuzz/run.sh.
fuzz: setup
	tests/fuzz/run.sh

format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp')

clean:
	rm -rf build build-test build-bench build-fuzz
