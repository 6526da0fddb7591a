# dcslam — the two commands: `make reproduce-table-5-2` (main job) and `make test` (tests).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
DCSLAM := $(VENV)/bin/dcslam
STAMP  := $(VENV)/.dcslam-installed

PROFILE    ?= quick
WORKSPACE  ?= workspace
KITTI_ROOT ?=
JOBS       ?= $(shell nproc 2>/dev/null || echo 1)
# SEEDS: training seeds per trained run (default: the profile's); e.g. make reproduce-beams SEEDS=2
SEEDS      ?=
REPRO_ARGS  = --profile $(PROFILE) --workspace $(WORKSPACE) --jobs $(JOBS) $(if $(KITTI_ROOT),--kitti $(KITTI_ROOT)) \
              $(if $(SEEDS),--seeds $(SEEDS))

.PHONY: setup python-env system-libs test test-cluster bench clean reproduce-table-5-2 reproduce-table-5-1 reproduce-beams reproduce-surface demo-icl results pages

# setup: Open3D's system library (libusb-1.0-0, by apt-get when missing and root), then the Python environment
# (python-env): pip installs uv, uv installs torch==2.13.0 (pinned here, not in the package) and dcslam with its test
# extra in parallel (the test extra alone: 24 s with an empty cache, 66 s by pip). FIND_LINKS: folders of wheels to
# look in first, by default those pip is configured with (PIP_FIND_LINKS, else pip's global.find-links: where a
# machine keeps torch's CPU build; uv reads no pip configuration). A torch 2.13.0 already in .venv (a CUDA build
# installed by hand) is kept.
FIND_LINKS ?= $(or $(PIP_FIND_LINKS),$(shell $(PYTHON) -m pip config get global.find-links 2>/dev/null))
setup: system-libs $(STAMP)

python-env: $(STAMP)

system-libs:
	@if ! ldconfig -p 2>/dev/null | grep -q libusb-1.0; then \
	  echo "installing libusb-1.0-0 (needed by Open3D)"; \
	  (apt-get update -qq && apt-get install -y -qq libusb-1.0-0) >/dev/null || \
	  echo "warning: could not install libusb-1.0-0; run 'apt-get install -y libusb-1.0-0' as root"; \
	fi

$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q uv
	$(PY) -m uv pip install -q --python $(PY) --compile-bytecode $(foreach d,$(FIND_LINKS),--find-links $(d)) \
	  torch==2.13.0 -e '.[test]'
	touch $(STAMP)

# every test, the slow end-to-end ones and the cluster ones included (CI runs this), a worker per core; PYTEST_ARGS='-m "not slow"'
# leaves the slow ones out. The cluster tests start a single-node Slurm here (tests/cluster/slurm.sh installs
# slurm-wlm and munge with apt-get when missing, as root; skipped with the reason elsewhere, failed under CI=true)
# TEST_JOBS: pytest-xdist workers, one per core by default; each test file runs whole on one worker, so module-wide
# fixtures (a smoke reproduction, the Slurm runs) are built once. TEST_JOBS=0 runs everything in this process.
# compileall: dcslam's byte code written once, so that the hundreds of Python processes the tests start (commands,
# worker pools, Slurm jobs) read it instead of compiling the sources each (where PYTHONDONTWRITEBYTECODE is set, as on
# the CI machines, Python never writes it itself: ~0.3 CPU-s per process).
# TEST_THREADS: threads per worker for torch and the BLAS libraries (OMP_NUM_THREADS and kin, inherited by the
# commands the tests start): one, as dcslam's own worker pools, since the workers already fill the cores and the
# tests' small tensors run slower, not faster, on several threads (docs/getting-started.md).
# PYTHONDONTWRITEBYTECODE= (empty: unset): pytest keeps the test modules it rewrote for its assertion messages, which
# each worker otherwise rewrites again on every run (9 CPU-s a worker; a fresh clone still pays it once).
PYTEST_ARGS  ?=
TEST_JOBS    ?= auto
TEST_THREADS ?= 1
TEST_ENV      = OMP_NUM_THREADS=$(TEST_THREADS) OPENBLAS_NUM_THREADS=$(TEST_THREADS) MKL_NUM_THREADS=$(TEST_THREADS) \
                PYTHONDONTWRITEBYTECODE=
test: setup
	$(PY) -m ruff check dcslam tests benchmarks examples
	$(PY) -m compileall -q -j 0 dcslam tests benchmarks examples >/dev/null
	$(TEST_ENV) $(PY) -m pytest -q $(if $(filter 0,$(TEST_JOBS)),,-n $(TEST_JOBS) --dist loadfile --no-loadscope-reorder) $(PYTEST_ARGS) tests

# only the tests on Slurm (dcslam reproduce --executor slurm), a few minutes
test-cluster: setup
	$(TEST_ENV) $(PY) -m pytest -q -m cluster tests/cluster

# The main job: generate KITTI-format drives (or read KITTI_ROOT=...), train the four recipes, predict, filter,
# run SLAM on every depth source, score, and print Table 5.2. PROFILE=thesis runs the thesis's scale (for a GPU).
reproduce-table-5-2: setup
	$(DCSLAM) reproduce --table 5.2 $(REPRO_ARGS)

reproduce-table-5-1: setup
	$(DCSLAM) reproduce --table 5.1 $(REPRO_ARGS)

# The beams experiment: every input (sparse, IP-Basic, SparseConvNet trained against annotated depth, against
# exact depth and against exact depth with the geometry losses, nconv unmasked and masked by its confidence,
# nconv-guided, nconv fine-tuned through the pose loss, annotated dense, exact) at 64/32/16/8 LiDAR beams, each
# completion and exact depth also with measured ICP sources (the B-beam pixels against the completed map); table,
# per-drive CSV and a PNG of localisation against beam count under $(WORKSPACE)/results/ (table_beams.*,
# beams_localisation.png).
reproduce-beams: setup
	$(DCSLAM) reproduce --table beams $(REPRO_ARGS)

# The surface experiment: sparse, IP-Basic, scanline, planefit (the completers that keep planes and scanlines) and
# exact depth at 64/16/8 LiDAR beams, each completion and exact depth also with measured ICP sources; nothing is
# trained. The beams table over these rows, with the robust comparison against sparse, under $(WORKSPACE)/results/
# (table_surface.*, surface_localisation.png).
reproduce-surface: setup
	$(DCSLAM) reproduce --table surface $(REPRO_ARGS)

# The thesis's appendix C.2: a DnCNN learns to remove Gaussian depth noise from the chamfer distance between maps
# alone. Generates indoor rooms in the ICL-NUIM layout (kept under $(WORKSPACE)/demo-icl/), trains, prints the
# before/after table; results under $(WORKSPACE)/results/demo-icl/. DEMO_ARGS passes options (e.g. --sigma 0.02).
DEMO_ARGS ?=
demo-icl: setup
	$(DCSLAM) demo-icl --workspace $(WORKSPACE) --force $(DEMO_ARGS)

# Committed results: copy $(WORKSPACE)/results/*.{md,csv} into results/$(NAME)/ with a provenance.json (commit,
# date, profile, command, machine); FORCE=1 replaces an earlier copy. Then `make pages` refreshes the tables of
# RESULTS.md and README.md from results/ (`dcslam score page PAGE --check` tells whether a page is current).
NAME    ?=
COMMAND ?= make reproduce-table-5-2 PROFILE=$(PROFILE)
MACHINE ?=
results: setup
	$(DCSLAM) score collect --name $(NAME) -w $(WORKSPACE) --profile $(PROFILE) --command "$(COMMAND)" \
	  $(if $(MACHINE),--machine "$(MACHINE)") $(if $(FORCE),--force)

pages: setup
	$(DCSLAM) score page RESULTS.md
	$(DCSLAM) score page README.md

# bench: every benchmarks/bench_*.py, with KISS-ICP (the bench extra, bench_slam.py's reference) installed first.
# BENCH_ARGS go to every script (each takes the options it knows). By default bench_slam.py runs one child at a
# time and every row three times, counting the fastest: repeats of one run spread ~1.4x even on a quiet machine
# (docs/benchmarks.md); BENCH_ARGS= gives one quicker, noisier pass.
BENCH_ARGS ?= --repeat 3 --jobs 1
bench: setup
	$(PY) -c 'import kiss_icp' 2>/dev/null || $(PY) -m uv pip install -q --python $(PY) -e '.[test,bench]'
	$(PY) benchmarks/run_all.py $(BENCH_ARGS)

clean:
	rm -rf $(VENV) workspace .pytest_cache
