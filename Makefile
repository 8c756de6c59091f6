# slamrun: the two commands that work on a fresh machine are `make campaign` and `make test`.
PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
SPEC   ?= configs/demo.yaml
ARGS   ?=

.PHONY: install install-dev campaign test bench lint images verify-images paper clean gpu-wheels gpu-check

# install: what running slamrun needs; install-dev: that and the test tools (pytest, ruff, evo, dask, ...)
install: $(VENV)/.installed

install-dev: $(VENV)/.installed-dev

# imagecorruptions without its dependencies: slamrun reads its frost pictures (ImageNet-C's frost); its code, which
# wants opencv-python and scikit-image, runs only in the tests, as the reference slamrun's corruptions are checked on
$(VENV)/.installed: pyproject.toml setup.py slamrun/core/_tumparse.c
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e .
	$(BIN)/python -m pip install -q --no-deps imagecorruptions==1.1.2
	touch $@

$(VENV)/.installed-dev: $(VENV)/.installed
	$(BIN)/python -m pip install -q --no-warn-conflicts -e '.[dev]'  # imagecorruptions is there without its deps
	touch $@

campaign: install
	$(BIN)/slamrun campaign $(SPEC) $(ARGS)

test: install-dev
	$(BIN)/python -m pytest $(ARGS)

bench: install-dev
	$(BIN)/python -m bench $(ARGS)

lint: install-dev
	$(BIN)/ruff check slamrun tests bench
	$(BIN)/ruff format --check slamrun tests bench

IMAGE_ARGS = $(foreach m,$(METHOD),--method $(m)) $(if $(SOURCES),--sources $(SOURCES)) $(if $(MARCH),--march $(MARCH))

images: install
	$(BIN)/slamrun images $(IMAGE_ARGS) $(ARGS)

verify-images: install
	$(BIN)/slamrun images --verify $(IMAGE_ARGS) $(ARGS)

paper: install
	$(BIN)/slamrun campaign configs/paper.yaml
	$(BIN)/slamrun campaign configs/paper-timing.yaml

clean:
	rm -rf $(VENV) results .cache

# The GPU check (scripts/gpu-check.sh): `make gpu-wheels` here fills .whl/ with what a GPU machine without network
# lacks (wheels for Python $(GPU_PY), Eigen's headers, the GPU methods' archives); there, `make gpu-check OUT=DIR`
# (METHOD=droid_slam or mast3r_slam for one of those, METHOD=all for every GPU method, their builds side by side;
# dpvo by default).
WHEELS ?= .whl
GPU_PY ?= 3.12
OUT ?= gpu-check-out

gpu-wheels: install
	PY=$(PYTHON) SLAMRUN_PY=$(BIN)/python scripts/gpu-wheels.sh $(WHEELS) $(GPU_PY)

gpu-check:
ifeq ($(METHOD),all)
	WHEELS=$(WHEELS) bash scripts/gpu-check-all.sh $(OUT)
else
	WHEELS=$(WHEELS) METHOD=$(or $(METHOD),dpvo) bash scripts/gpu-check.sh $(OUT)
endif
