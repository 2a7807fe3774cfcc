# physinfer — two commands on a fresh machine: `make demo` and `make test`.
SHELL := /bin/bash
PY ?= python3
VENV := .venv
BIN := $(VENV)/bin
# torch first, from the machine's own wheel (CPU here); the constraint keeps every later
# install from replacing it with a CUDA build.
TORCH_SPEC ?= torch==2.13.0
CONSTRAINTS := $(VENV)/constraints.txt
# libgl1 and libglx0: pyglet (imported by pyrender) loads libGL.so.1 even when headless.
EGL_PACKAGES := libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libglx0
# pyrender 0.1.45 pins PyOpenGL==3.1.0, which fails on Python 3.12+ ("No array-type handler
# for type _ctypes.type"; fixed in 3.1.7). pip cannot resolve a newer one beside the pin, so
# it is installed as a step of its own, last (pip warns about pyrender's pin; it renders).
PYOPENGL_SPEC ?= PyOpenGL>=3.1.7
# Headless Chromium and its WebDriver: the tests open every run's report.html in a real browser.
BROWSER_PACKAGES := chromium chromium-driver
PIP := $(BIN)/pip --disable-pip-version-check
# pip warns once per package about index folders this machine lacks; hide only that line.
QUIET_PIP := 2> >(grep -v "is ignored: it is neither" >&2)
# ... and, installing PyOpenGL, the three lines saying pyrender pins 3.1.0 (known; see above).
QUIET_PYOPENGL := 2> >(grep -v -e "is ignored: it is neither" -e "dependency resolver" -e "pyrender" >&2)
export PYOPENGL_PLATFORM ?= egl
# pyglet (imported by pyrender) looks for an X display unless told it is headless.
export PYGLET_HEADLESS ?= 1

.PHONY: install system-deps demo test test-all lint docs bench pretrained posterior posterior-sizes posterior-camera posterior-corners posterior-pendulum posterior-hanging-cloth clean

$(BIN)/python:
	$(PY) -m venv $(VENV)

$(VENV)/.installed: pyproject.toml examples/pendulum/pyproject.toml | $(BIN)/python
	$(MAKE) --no-print-directory system-deps
	$(PIP) install -q "$(TORCH_SPEC)" $(QUIET_PIP)
	$(BIN)/python -c "import torch; print('torch==' + torch.__version__)" > $(CONSTRAINTS)
	$(PIP) install -q -c $(CONSTRAINTS) -e ".[dev]" $(QUIET_PIP)
	$(PIP) install -q -c $(CONSTRAINTS) -e examples/pendulum $(QUIET_PIP)
	$(PIP) install -q -c $(CONSTRAINTS) "$(PYOPENGL_SPEC)" $(QUIET_PYOPENGL)
	$(BIN)/python -c "import physinfer, physinfer_flag, pendulum_example, pyrender"
	touch $@

install: $(VENV)/.installed

# Headless OpenGL through EGL on Mesa's CPU driver (llvmpipe), and headless Chromium; each
# installed only when missing.
system-deps:
	@if ! ldconfig -p | grep -q "libEGL_mesa.so" || ! ldconfig -p | grep -q "libGL.so.1" \
		|| ! ldconfig -p | grep -q "libGLX.so.0" || ! ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1; then \
		echo "installing $(EGL_PACKAGES) (headless EGL)"; \
		if [ "$$(id -u)" = 0 ]; then apt-get update -qq && apt-get install -y -qq $(EGL_PACKAGES) > /dev/null; \
		else sudo apt-get update -qq && sudo apt-get install -y -qq $(EGL_PACKAGES) > /dev/null; fi; \
	fi
	@if ! command -v chromium >/dev/null || ! command -v chromedriver >/dev/null; then \
		echo "installing $(BROWSER_PACKAGES) (report.html browser test)"; \
		if [ "$$(id -u)" = 0 ]; then apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(BROWSER_PACKAGES) > /dev/null; \
		else sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $(BROWSER_PACKAGES) > /dev/null; fi; \
	fi

demo: install
	$(BIN)/physinfer refine --plugin flag --out runs/demo --overwrite

# Two pytest-xdist workers that take tests from each other's queues when idle (worksteal; a
# module's fixtures may be built on both): 1,140 tests in 14.5 and 15.1 min on 2 cores,
# 2026-11-27, where one file per worker (loadfile) took 15.2 min. On a slower 2-core box,
# 2026-11-29, the same suite took 15.6-16.8 min between runs; after three trims 1,138 tests
# in 14.9 min (16.2 with two). Each worker's share starts with its longest modules
# (tests/conftest.py): 1,147 tests in 14.2 min against 15.3 in collection order, 2026-11-29;
# 1,183 in 15.0 min on 2026-11-30, after which one 38-s accuracy test became `slow`.
# PYTEST_WORKERS=0 runs in-process.
PYTEST_WORKERS ?= 2
PYTEST_XDIST = $(if $(filter 0,$(PYTEST_WORKERS)),,-n $(PYTEST_WORKERS) --dist worksteal)

# --durations: the slowest tests in every log (the 15-minute budget is watched from them).
test: install
	$(BIN)/python -m pytest -q -p no:cacheprovider $(PYTEST_XDIST) --durations=30

test-all: install
	$(BIN)/python -m pytest -q -p no:cacheprovider $(PYTEST_XDIST) -m ""

lint: install
	$(BIN)/ruff check core plugins tests examples benchmarks

# The API reference (pdoc, Google-style docstrings) of the public API: the library API
# (physinfer.api), the top-level names,
# the roles, parameters, value types, hooks and registry, rendering helpers, settings and
# the testing kit; the other physinfer modules are left out ('!physinfer\..*'). Open
# docs/api/index.html. tests/core/test_api_docs.py reads this list.
API_MODULES := physinfer '!physinfer\..*' physinfer.roles physinfer.parameters physinfer.types \
	physinfer.errors physinfer.hooks physinfer.registry physinfer.plugins physinfer.rendering \
	physinfer.settings physinfer.testing physinfer.testing.effects physinfer.testing.sensitivity \
	physinfer.testing.fixtures physinfer.api physinfer.api.options physinfer.api.results
docs: install
	rm -rf docs/api
	$(BIN)/python -m pdoc -d google -o docs/api $(API_MODULES)

# The flag's shipped SDN weights: generate the cpu FlagSim preset (resumes), train (resumes;
# 15 epochs on 60-frame inputs, well under an hour on 2 cores), export float16 weights.
pretrained: install
	$(BIN)/physinfer dataset generate --plugin flag --preset cpu --seed 0 --gray --out runs/flagsim-cpu
	$(BIN)/physinfer train --plugin flag --data runs/flagsim-cpu --out runs/sdn-cpu --epochs 15 --frames 60
	$(BIN)/python -c "from physinfer_flag.sdn.weights import export_weights; \
		print(export_weights('runs/sdn-cpu', info={'made_by': 'make pretrained'}))"

# The flag's shipped posterior estimator: 800 training and 200 held-out 2.4-s simulations
# (resumes; about 25 min on 2 cores), sent through camera effects, H.264 and infer's
# conditioning as users' videos are and embedded by the spectral embedder over all 60 frames
# (cached beside the data), five seeded MAFs with sbi (about a minute), checked on the held-out
# split as given before writing, then the calibration (as given, and as stored beside it).
posterior: install
	$(BIN)/physinfer dataset generate --plugin flag --preset cpu --sims 800,0,200 --renders-per-sim 1 \
		--frames 60 --size 224 --gray --seed 21 --out runs/flag-posterior
	$(BIN)/physinfer posterior train --plugin flag --data runs/flag-posterior --device cpu --seed 0 \
		--embedder spectral --embedder-frames 60 --density maf --patience 20 --ensemble 5 \
		--out plugins/flag/physinfer_flag/data/posterior_default.safetensors --overwrite
	$(BIN)/physinfer evaluate calibration --plugin flag --data runs/flag-posterior --device cpu \
		--out runs/flag-posterior-calibration

# The flag's shipped estimator told the camera and light (chosen by infer --render-set): the
# dataset and cached embeddings of `posterior` (the generate line resumes), each clip's six numeric
# render settings (camera angles, field of view, framing, light, ambient) appended to its
# embedding (--told-camera), five seeded MAFs (about 8 min on 2 cores); then its calibration.
posterior-camera: install
	$(BIN)/physinfer dataset generate --plugin flag --preset cpu --sims 800,0,200 --renders-per-sim 1 \
		--frames 60 --size 224 --gray --seed 21 --out runs/flag-posterior
	$(BIN)/physinfer posterior train --plugin flag --data runs/flag-posterior --device cpu --seed 0 \
		--embedder spectral --embedder-frames 60 --density maf --patience 20 --ensemble 5 --told-camera \
		--out plugins/flag/physinfer_flag/data/posterior_camera.safetensors --overwrite
	$(BIN)/physinfer evaluate calibration --plugin flag --data runs/flag-posterior --device cpu \
		--posterior plugins/flag/physinfer_flag/data/posterior_camera.safetensors \
		--out runs/flag-posterior-camera-calibration

# The flag's shipped estimator for other sizes: 800 + 200 simulations whose flag length and
# height are drawn per simulation (log-uniform, 0.9-3 m × 0.6-2 m; about 20 min on 2 cores),
# the same embedder and flows as `posterior`, with the size as an input; then its calibration.
posterior-sizes: install
	$(BIN)/physinfer dataset generate --plugin flag --preset cpu --sims 800,0,200 --renders-per-sim 1 \
		--frames 60 --size 224 --gray --seed 22 --scene-range flag_length=0.9:3 --scene-range flag_height=0.6:2 \
		--out runs/flag-posterior-sizes
	$(BIN)/physinfer posterior train --plugin flag --data runs/flag-posterior-sizes --device cpu --seed 0 \
		--embedder spectral --embedder-frames 60 --density maf --patience 20 --ensemble 5 \
		--out plugins/flag/physinfer_flag/data/posterior_sizes.safetensors --overwrite
	$(BIN)/physinfer evaluate calibration --plugin flag --data runs/flag-posterior-sizes --device cpu \
		--posterior plugins/flag/physinfer_flag/data/posterior_sizes.safetensors \
		--out runs/flag-posterior-sizes-calibration

# The flag's shipped estimator for a flag pinned at its two top corners (a banner between two
# points): 480 + 120 simulations of sizes drawn as for `posterior-sizes` (about 35 min on 2
# cores), the same embedder and flows, the size as an input; then its calibration.
posterior-corners: install
	$(BIN)/physinfer dataset generate --plugin flag --preset cpu --sims 480,0,120 --renders-per-sim 1 \
		--frames 60 --size 224 --gray --seed 23 --scene-set pinning=corners \
		--scene-range flag_length=0.9:3 --scene-range flag_height=0.6:2 --out runs/flag-posterior-corners
	$(BIN)/physinfer posterior train --plugin flag --data runs/flag-posterior-corners --device cpu --seed 0 \
		--embedder spectral --embedder-frames 60 --density maf --patience 20 --ensemble 5 \
		--out plugins/flag/physinfer_flag/data/posterior_corners.safetensors --overwrite
	$(BIN)/physinfer evaluate calibration --plugin flag --data runs/flag-posterior-corners --device cpu \
		--posterior plugins/flag/physinfer_flag/data/posterior_corners.safetensors \
		--out runs/flag-posterior-corners-calibration

# The pendulum's shipped estimator: 1,200 training and 300 held-out 8-s simulations with every
# look randomised (64 px RGB; about 10 min on 2 cores), sent through camera effects, H.264 and
# infer's conditioning and embedded by the motion embedder over the first 8 s (160 frames at
# 20 fps), three seeded neural spline flows, checked on the held-out split as given, then the
# calibration.
posterior-pendulum: install
	$(BIN)/physinfer dataset generate --plugin pendulum --sims 1200,0,300 --renders-per-sim 1 \
		--frames 200 --size 64 --rgb --seed 41 --out runs/pendulum-posterior
	$(BIN)/physinfer posterior train --plugin pendulum --data runs/pendulum-posterior --device cpu --seed 0 \
		--embedder motion --embedder-frames 160 --ensemble 3 --overwrite \
		--out plugins/pendulum/physinfer_pendulum/data/posterior_default.safetensors
	$(BIN)/physinfer evaluate calibration --plugin pendulum --data runs/pendulum-posterior --device cpu \
		--posterior plugins/pendulum/physinfer_pendulum/data/posterior_default.safetensors \
		--out runs/pendulum-posterior-calibration

# The hanging cloth's shipped estimator: 600 training and 150 held-out simulations of the default
# fabric at fan W2 (32 frames, the phenomenon's clip; about 30 min on 2 cores), sent through
# camera effects, H.264 and infer's conditioning, embedded by `spectral`, five seeded MAFs,
# checked on the held-out split as given, then the calibration.
posterior-hanging-cloth: install
	$(BIN)/physinfer dataset generate --plugin hanging_cloth --sims 600,0,150 --renders-per-sim 1 \
		--frames 32 --size 224 --gray --seed 31 --out runs/hc-posterior
	$(BIN)/physinfer posterior train --plugin hanging_cloth --data runs/hc-posterior --device cpu --seed 0 \
		--density maf --patience 20 --ensemble 5 --overwrite \
		--out plugins/hanging_cloth/physinfer_hanging_cloth/data/posterior_default.safetensors
	$(BIN)/physinfer evaluate calibration --plugin hanging_cloth --data runs/hc-posterior --device cpu \
		--posterior plugins/hanging_cloth/physinfer_hanging_cloth/data/posterior_default.safetensors \
		--out runs/hc-posterior-calibration

clean:
	rm -rf $(VENV) runs .pytest_cache
