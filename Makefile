# blendsim: the two commands are `make demo` and `make test`. Every target installs what it
# needs (idempotently, saying what it does) on a fresh Debian machine.

SHELL := /bin/bash
.SHELLFLAGS := -eu -o pipefail -c
.DEFAULT_GOAL := help

CARGO ?= cargo
PYTHON ?= python3
BIN := target/release/blendsim
CHECKERS := tests/checkers
# apt-get needs root; use sudo when not already root.
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
USD_CORE := usd-core==26.11
# The Alembic C++ library's Python bindings, for the .abc cache reader (beside usd-core).
ALEMBIC := alembic3d==1.8.12.1
# Blender as a Python module, for the Blender checker: bpy 4.2.0 needs exactly Python 3.11, so
# it lives in a venv of its own under build/ (the system Python is left untouched). The tests
# find it there, or at $$BLENDSIM_BLENDER_PYTHON.
BPY := bpy==4.2.0
PYTHON311 ?= python3.11
BLENDER_VENV := build/blender-venv

# Ray (PyPI `ray`) for the cluster driver in cluster/ (`blendsim-ray`, docs/cluster.md): ray and
# the driver (editable) in a Python 3.11 venv of their own under build/.
RAY_VERSION := 2.60.0
RAY := ray==$(RAY_VERSION)
RAY_VENV := build/ray-venv

# `make batch SCENES=folder`: bake every *.toml of a folder (works with -j).
SCENES ?= fixtures/paper
BATCH_OUT ?= build/batch

.PHONY: deps-ray batch-ray test-ray bench-ray help build demo readme-image test lint completions install deps-rust-tools fuzz tables test-deps deps-tetgen deps-usd deps-fbx-samples deps-alembic deps-npm deps-chromium deps-blender bench bench-demo bench-warm bench-writers bench-cache bench-scale bench-global-step batch batch-caches clean

help:
	@echo "make demo     bake the bundled twisting-prism scene into build/demo and print its report"
	@echo "make readme-image  the README's picture (the demo report's volume plot) into docs/images/demo-volume.svg"
	@echo "make test     run the whole test suite (installs tetgen, Assimp's FBX test files, usd-core, chromium, npm checkers, Blender's bpy, Ray)"
	@echo "make lint     cargo fmt --check and cargo clippy -D warnings, without and with the test hooks (part of make test)"
	@echo "make tables   print the reliability tables: the bad-input corpus (input, exit 1, message) and the kill tests (signal x phase -> folder)"
	@echo "make fuzz     fuzz the input readers for longer (FUZZ_CASES=$(FUZZ_CASES) cases per property)"
	@echo "make bench    print the solver benchmark (the paper's Table 1 on this machine)"
	@echo "make bench-demo   print where the demo bake's time goes: the process, each phase, one solver iteration, Python's start-up"
	@echo "make bench-warm   print cold against warm re-bakes (bake --from): unchanged inputs and one edited key, the demo, the 20-key body and DINO"
	@echo "make bench-writers print the full-frame writers' MB/s (usda, usdc, glb) beside the disk's"
	@echo "make bench-scale  print whole-bake time and peak memory of production-size surfaces (cage, 20 keys, 100k vertices)"
	@echo "make bench-global-step print the global step's direct (one thread and all), iterative and modal set-up and solve on many-keys bodies"
	@echo "make bench-cache  print vertex-cache sizes, times and peak memory per format (100k vertices x 300 frames)"
	@echo "make batch    bake every scene in SCENES=$(SCENES) into $(BATCH_OUT)/NAME (use -j), then summary.html/.md/.csv"
	@echo "make batch-ray  the same scenes as make batch, one bake per Ray task on the cluster at RAY_ADDRESS (or a local one): docs/cluster.md"
	@echo "make test-ray   the cluster tests alone (part of make test): a local Ray head and worker node of their own"
	@echo "make bench-ray  make -j2 batch against blendsim-ray on a local 2-node cluster (21 scenes): batch times, per-task overhead and bytes"
	@echo "make batch-caches  bake the simulated test caches in every format into build/batch-caches, with summary.html/.md/.csv"
	@echo "make completions  shell completions (bash, zsh, fish) and man pages into build/share"
	@echo "make install  the binary, completions and man pages under PREFIX=$(PREFIX)"
	@echo "make test-deps / build / clean"

build:
	@echo "==> building blendsim (release)"
	$(CARGO) build --release --locked

deps-tetgen:
	@if command -v tetgen >/dev/null 2>&1; then \
		echo "==> tetgen: already installed"; \
	else \
		echo "==> installing tetgen (apt-get)"; \
		$(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq tetgen; \
	fi

# The Assimp project's test files (FBX written by other tools), read by the studio cache tests.
deps-fbx-samples:
	@if [ -d /usr/share/assimp/models/FBX ]; then \
		echo "==> assimp-testmodels: already installed"; \
	else \
		echo "==> installing assimp-testmodels (apt-get): FBX files written by other tools, for the tests"; \
		$(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq assimp-testmodels; \
	fi

deps-usd:
	@if $(PYTHON) -c 'import pxr' >/dev/null 2>&1; then \
		echo "==> usd-core (python pxr): already installed"; \
	else \
		echo "==> installing $(USD_CORE) (pip)"; \
		$(PYTHON) -m pip install --quiet --disable-pip-version-check $(USD_CORE); \
	fi

deps-alembic:
	@if $(PYTHON) -c 'import alembic3d' >/dev/null 2>&1; then \
		echo "==> alembic3d (python Alembic bindings): already installed"; \
	else \
		echo "==> installing $(ALEMBIC) (pip)"; \
		$(PYTHON) -m pip install --quiet --disable-pip-version-check $(ALEMBIC); \
	fi

deps-chromium:
	@if [ -x /usr/bin/chromium ]; then \
		echo "==> chromium: already installed"; \
	else \
		echo "==> installing chromium (apt-get)"; \
		$(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; \
	fi

# The npm checkers (gltf-validator, three, Babylon.js, gltfpack, playwright-core), pinned by package-lock.json;
# reinstalled only when the lock file changes.
deps-npm: $(CHECKERS)/node_modules/.installed
$(CHECKERS)/node_modules/.installed: $(CHECKERS)/package.json $(CHECKERS)/package-lock.json
	@echo "==> installing the glTF checkers (npm ci in $(CHECKERS))"
	cd $(CHECKERS) && npm ci --no-audit --no-fund --loglevel=error
	@touch $@

# Blender's shared libraries need a few X and GL client libraries even when nothing is drawn.
BLENDER_APT := python3.11 python3.11-venv libxrender1 libxxf86vm1 libxfixes3 libxi6 libxkbcommon0 libsm6 libgl1 libegl1
deps-blender:
	@if $(BLENDER_VENV)/bin/python -c 'import bpy' >/dev/null 2>&1; then \
		echo "==> $(BPY) (Blender as a Python module): already installed in $(BLENDER_VENV)"; \
	else \
		if ! command -v $(PYTHON311) >/dev/null 2>&1 || ! $(PYTHON311) -c 'import ensurepip, venv' >/dev/null 2>&1 || ! ldconfig -p | grep libXrender.so.1 >/dev/null; then \
			echo "==> installing Python 3.11 with venv and Blender's X/GL client libraries (apt-get)"; \
			$(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(BLENDER_APT); \
		fi; \
		echo "==> installing $(BPY) (pip, a 519 MB wheel) into the venv $(BLENDER_VENV)"; \
		rm -rf $(BLENDER_VENV); \
		$(PYTHON311) -m venv $(BLENDER_VENV); \
		$(BLENDER_VENV)/bin/python -m pip install --quiet --disable-pip-version-check $(BPY); \
		$(BLENDER_VENV)/bin/python -c 'import bpy; print("==> bpy", bpy.app.version_string)'; \
	fi

deps-ray:
	@if $(RAY_VENV)/bin/python -c 'import ray, sys; sys.exit(ray.__version__ != "$(RAY_VERSION)")' >/dev/null 2>&1; then \
		echo "==> $(RAY): already installed in $(RAY_VENV)"; \
	else \
		if ! command -v $(PYTHON311) >/dev/null 2>&1 || ! $(PYTHON311) -c 'import ensurepip, venv' >/dev/null 2>&1; then \
			echo "==> installing Python 3.11 with venv (apt-get)"; \
			$(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq python3.11 python3.11-venv; \
		fi; \
		echo "==> installing $(RAY) (pip, about 285 MB) into the venv $(RAY_VENV)"; \
		rm -rf $(RAY_VENV); \
		$(PYTHON311) -m venv $(RAY_VENV); \
		$(RAY_VENV)/bin/python -m pip install --quiet --disable-pip-version-check $(RAY); \
		$(RAY_VENV)/bin/python -c 'import ray; print("==> ray", ray.__version__)'; \
	fi
	@# The driver, editable from this checkout (a venv copied from another one points there).
	@if [ "$$($(RAY_VENV)/bin/python -c 'import blendsim_ray, os; print(os.path.dirname(os.path.dirname(blendsim_ray.__file__)))' 2>/dev/null)" = "$(CURDIR)/cluster" ]; then \
		echo "==> blendsim-ray (cluster/, editable): already installed in $(RAY_VENV)"; \
	else \
		echo "==> installing blendsim-ray (cluster/, editable; pip fetches setuptools to build it) into the venv $(RAY_VENV)"; \
		$(RAY_VENV)/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e cluster; \
	fi

test-deps: deps-tetgen deps-fbx-samples deps-usd deps-alembic deps-npm deps-chromium deps-blender deps-ray

demo: build deps-tetgen
	@echo "==> baking fixtures/demo/twist.toml into build/demo"
	$(BIN) bake fixtures/demo/twist.toml --out build/demo
	@echo
	@cat build/demo/report.md
	@echo "plots and a player: build/demo/report.html (open it in a browser)"

# The README's picture: the volume plot of the demo's report.html, as a standalone SVG.
readme-image: demo
	@echo "==> docs/images/demo-volume.svg from build/demo/report.html"
	@python3 -c 'import re; s = open("build/demo/report.html").read(); \
		m = re.search(r"<svg[^>]*id=\"plot-volume\".*?</svg>", s, re.S); \
		open("docs/images/demo-volume.svg", "w").write(m.group(0) + "\n")'

# Style and lints, as the suite runs them: rustfmt (rustfmt.toml) and clippy with the lint set
# of Cargo.toml's [lints], warnings as errors.
deps-rust-tools:
	@if $(CARGO) fmt --version >/dev/null 2>&1 && $(CARGO) clippy --version >/dev/null 2>&1; then \
		echo "==> rustfmt and clippy: already installed"; \
	else \
		echo "==> installing rustfmt and clippy (rustup component add)"; \
		rustup component add rustfmt clippy; \
	fi

lint: deps-rust-tools
	@echo "==> checking the formatting (cargo fmt --check)"
	$(CARGO) fmt --check
	@echo "==> linting (cargo clippy --all-targets, warnings are errors; without and with the test hooks)"
	$(CARGO) clippy --release --locked --all-targets -- -D warnings
	$(CARGO) clippy --release --locked --all-targets --features test-hooks -- -D warnings

# The property tests draw their cases from a fixed seed here, so that a run of the suite is
# repeatable and CI cannot turn red on a case no earlier run drew; `make fuzz` (and a plain
# `cargo test`) draw a new seed every run. TEST_SEED=N runs the suite on another seed.
TEST_SEED ?= 20261202
# The cluster tests (cluster/tests): a local Ray cluster of their own (a head and worker nodes on
# free ports, under a temp dir; stopped by process id, never by `ray stop`). 2 to 3 minutes on 2 cores.
test-ray: build deps-ray deps-tetgen
	@echo "==> the Ray cluster tests (blendsim-ray on a local head and worker node started by the tests)"
	BLENDSIM=$(CURDIR)/$(BIN) $(RAY_VENV)/bin/python -m unittest discover -s cluster/tests -v

test: test-deps lint test-ray
	@echo "==> running the test suite (release build with the test hooks; property tests seeded with $(TEST_SEED))"
	PROPTEST_RNG_SEED=$(TEST_SEED) $(CARGO) test --release --locked --features test-hooks
	@echo "==> checking the API documentation builds without warnings (cargo doc)"
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --no-deps --locked

# The closing tables of the reliability work (issue 7), printed by the tests that check them:
# every bad input of the corpus with its one-line message (each exits 1 and leaves the output
# folder as it was), every bad stage file, and the kill tests (SIGINT, SIGTERM, SIGKILL at every
# phase of a bake -> the state of the output folder, the child process, the leftovers).
tables: test-deps
	@echo "==> the bad-input corpus, the bad stage files, the kill tests (tables on stderr)"
	$(CARGO) test --release --locked --features test-hooks --test integration -- --nocapture --test-threads=1 --exact \
		cli_errors::corpus_of_bad_inputs cli_errors::corpus_of_bad_stage_files \
		cli_interrupt::sigint_at_every_phase cli_interrupt::sigterm_at_every_phase cli_interrupt::sigkill_at_every_phase

# The readers' property tests (src/pipeline/fuzz_readers.rs) run 10,000 cases per property in `make test`;
# this runs many more (random bytes and mutations of valid files, with shrinking). The filter
# also runs the vertex-cache readers' properties (src/formats/cache/fuzz.rs, a fixed 3,000 cases).
FUZZ_CASES ?= 1000000
ifndef FUZZ_SEED
FUZZ_SEED := $(shell od -An -N4 -tu4 /dev/urandom | tr -d ' ')
endif
fuzz:
	@echo "==> fuzzing the OBJ, MEDIT, TetGen, selection and scene readers ($(FUZZ_CASES) cases per property, seed $(FUZZ_SEED): FUZZ_SEED=$(FUZZ_SEED) make fuzz repeats this run)"
	PROPTEST_RNG_SEED=$(FUZZ_SEED) PROPTEST_CASES=$(FUZZ_CASES) $(CARGO) test --release --locked --lib fuzz -- --nocapture

bench: build deps-tetgen
	@echo "==> solver benchmark (medians; mind the load average printed with it)"
	$(CARGO) bench --locked --bench solver
	@echo "==> cache benchmark: automatic keys, fit, bytes against full frame, PCA and gltfpack (caches, the demo and paper scenes)"
	$(CARGO) bench --locked --bench cache

# The demo bake taken apart (issue 11: under 0.25 s), medians of REPEATS (5).
bench-demo: build deps-tetgen deps-usd
	@echo "==> demo benchmark: where the bake's time goes (mind the load average printed with it)"
	$(CARGO) bench --locked --bench demo

# Warm re-bakes (`bake --from`) against cold bakes: the demo, the 20-key body and, with the paper's assets,
# DINO (`WARM_CASES=20-key` runs only the rows whose names hold that word).
bench-warm: build deps-tetgen
	@echo "==> warm re-bake benchmark: cold against --from (mind the load average printed with it)"
	$(CARGO) bench --locked --bench warm

# The full-frame writers' speed beside the disk's sequential write speed.
bench-writers: build
	@echo "==> writers benchmark: MB/s per format and the disk's (mind the load average printed with it)"
	$(CARGO) bench --locked --bench writers

# The scaling table (issue 11): production-size bakes through the CLI, one process per row
# (prism series, 20 keys, CHEB-style volume, 25k and 100k cages); peak memory by GNU time
# (Debian package `time`). `SCALE_CASES=10k,100k` runs the rows whose names hold those words.
bench-scale: build deps-tetgen
	@command -v /usr/bin/time >/dev/null 2>&1 || { echo "==> installing GNU time (apt-get)"; $(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq time; }
	@echo "==> scale benchmark: whole bakes of production-size surfaces (mind the load average printed with it)"
	$(CARGO) bench --locked --bench scale

# The global step's three methods on many-keys bodies (TetGen makes the prisms).
bench-global-step: build deps-tetgen
	@echo "==> global step benchmark: direct, iterative and modal (mind the load average printed with it)"
	$(CARGO) bench --locked --bench global_step

# Peak memory is measured with GNU time (Debian package `time`).
bench-cache: deps-usd
	@command -v /usr/bin/time >/dev/null 2>&1 || { echo "==> installing GNU time (apt-get)"; $(SUDO) apt-get update -qq && $(SUDO) env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq time; }
	@echo "==> vertex-cache benchmark (streaming readers and writers; mind the load average printed with it)"
	$(CARGO) bench --locked --bench cache_io

SCENE_NAMES := $(basename $(notdir $(wildcard $(SCENES)/*.toml)))
batch: $(foreach n,$(SCENE_NAMES),$(BATCH_OUT)/$(n)/report.json)
	@baked="$(dir $(wildcard $(BATCH_OUT)/*/report.json))"; \
	if [ -z "$$baked" ]; then echo "==> nothing baked (every scene was skipped)"; exit 0; fi; \
	for d in $$baked; do echo "$${d}report.md"; done; \
	$(BIN) report --batch $$baked -o $(BATCH_OUT); \
	echo "summary: $(BATCH_OUT)/summary.html, $(BATCH_OUT)/summary.md, $(BATCH_OUT)/summary.csv"

# The same bakes as `make batch`, one Ray task per scene (cluster/, docs/cluster.md): on the
# cluster at RAY_ADDRESS, or on one this machine runs (`ray start --head`), or else on a Ray
# started for this batch alone. BATCH_RAY_FLAGS passes more options (--max-time 10m ...).
BATCH_RAY_FLAGS ?=
batch-ray: build deps-ray
	$(RAY_VENV)/bin/blendsim-ray batch $(wildcard $(SCENES)/*.toml) --out $(BATCH_OUT) --blendsim $(BIN) $(BATCH_RAY_FLAGS)

# The same 21 scenes (the paper's, variations of the demo) through `make -j2 batch` and through
# blendsim-ray on a local cluster of two 1-CPU nodes: whole-batch times, per-task overhead and
# bytes moved (docs/cluster.md). BENCH_RAY_SCENES=N for another count.
bench-ray: build deps-ray deps-tetgen
	@echo "==> cluster benchmark: make -j2 batch against blendsim-ray on 2 local nodes (mind the load average printed with it)"
	$(RAY_VENV)/bin/python cluster/bench/bench_ray.py

# The simulated test caches (rapier3d bar, 2 and 1 Hz, every cache format) baked and summarized.
batch-caches: deps-usd
	BLENDSIM_BATCH_DIR=$(CURDIR)/build/batch-caches $(CARGO) test --release --locked --test integration cache_bake::batch_of_the_generated_caches -- --ignored --nocapture

# Each bake writes a depfile (every mesh, selection, texture and cache it read), so editing any
# of them re-bakes that scene. A scene whose files are missing (the paper's assets live beside
# the clone, in ../shared/assets) is skipped with one line, so `make batch` works on any clone.
$(BATCH_OUT)/%/report.json: $(SCENES)/%.toml | build deps-tetgen
	@missing=$$(grep -oE '"[^"]+\.(obj|mesh|dmat|txt|pc2|mdd|glb|gltf|usd|usda|usdc)"' $< | tr -d '"' | sort -u \
		| while read -r f; do [ -e "$(<D)/$$f" ] || echo "$$f"; done | head -n 1); \
	if [ -n "$$missing" ]; then echo "==> skipping $*: $(<D)/$$missing is missing (the paper's assets are not beside this clone)"; \
	else echo "$(BIN) bake $< -o $(@D) --depfile $(BATCH_OUT)/$*.d --quiet"; $(BIN) bake $< -o $(@D) --depfile $(BATCH_OUT)/$*.d --quiet; fi

-include $(wildcard $(BATCH_OUT)/*.d)

# Shell completions and man pages, generated from the command-line definitions.
completions: build
	@echo "==> generating shell completions and man pages into build/share"
	$(BIN) generate completions bash -o build/share/bash-completion/completions
	$(BIN) generate completions zsh -o build/share/zsh/site-functions
	$(BIN) generate completions fish -o build/share/fish/vendor_completions.d
	$(BIN) generate man -o build/share/man/man1

# `make install PREFIX=/usr/local`: the binary, its completions and man pages.
PREFIX ?= $(HOME)/.local
install: completions
	@echo "==> installing blendsim, its completions and man pages under $(PREFIX)"
	install -Dm755 $(BIN) $(PREFIX)/bin/blendsim
	cd build/share && find . -type f -exec install -Dm644 {} $(PREFIX)/share/{} \;

clean:
	rm -rf build
