# NavArena. Two commands on a fresh machine:
#   make dataset   # installs what it needs, then runs the pipeline on the built-in scene set
#   make test      # installs what it needs, then runs the tests
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
ARGS ?=
CUDA ?=
WHEELS ?=
GSPLAT_BUILD ?=

.PHONY: bench-realism bench-tour docs release verify-release bench-release bench-stale setup-gpu test-gpu bench-gpu bench-multi-gpu bench-render-check bench-screening bench-trained-scan setup dataset test lint test-all test-faults test-slurm bench-scale bench bench-real bench-spatial bench-spatial-gpu bench-episodes bench-eval bench-eval-gpu bench-semantics bench-semantics-gpu eval submit clean

# pip byte-compiles every package at install (torch: 18 s, 8 s with --no-compile): once, in one
# process; with --no-compile every process that first imports a module compiles it, and make test's
# processes start side by side: the set-up gained 29 s and the tests lost more (2026-11-27)
PIP := $(BIN)/python -m pip install -q
$(STAMP): pyproject.toml scripts/torchvision_fix.py
	test -x $(BIN)/python || $(PY) -m venv $(VENV)
	$(PIP) --upgrade pip
	# the CPU build of torch (an unpinned torch would pull several GB of CUDA packages)
	$(PIP) "torch==2.13.0" || $(PIP) torch --index-url https://download.pytorch.org/whl/cpu
	# the consumer library (navcore, navarena) editable, with the pipeline project's dependency groups
	# (pyproject.toml [dependency-groups]; pip >= 25.1)
	$(PIP) -e ".[gpu,lerobot,media,open_vocab,pretrained]" --group pipeline --group test --group bench --group docs
	# the pipeline (pipeline/, stages/) is the checkout's own, never in the wheel: this venv imports it
	# from here, wherever it runs (navarena run, python -m pipeline, Dask workers)
	$(BIN)/python -c "import pathlib, sysconfig; pathlib.Path(sysconfig.get_paths()['purelib'], 'navarena_checkout.pth').write_text(str(pathlib.Path.cwd()) + chr(10))"
	# the lerobot package and the torchvision / torchcodec it imports, next to our CPU torch 2.13:
	# torchvision 0.28.0 is the release made for torch 2.13, but PyPI builds it for CUDA torch, so its
	# operators cannot load here; scripts/torchvision_fix.py (a .pth import hook) lets its Python part load
	$(PIP) --no-deps "lerobot==0.4.4" "torchvision==0.28.0" "torchcodec==0.13.0"
	$(BIN)/python scripts/torchvision_fix.py install
	sh scripts/system_packages.sh
	touch $(STAMP)

setup: $(STAMP)

# the documentation site into site/ (MkDocs Material; --strict: a broken link or a missing page fails)
docs: $(STAMP)
	$(BIN)/python -m pipeline.config_reference --check
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict

# a CUDA machine in one command (scripts/setup_gpu.sh): CUDA torch matching the driver (CUDA=12.8 to
# choose), gsplat 1.5.3 with its kernels compiled once, the segmenter extras, then the ready check;
# offline from a folder of wheels with WHEELS=dir. Stops with a clear message without a GPU.
setup-gpu:
	PY=$(PY) VENV=$(VENV) CUDA=$(CUDA) WHEELS=$(WHEELS) GSPLAT_BUILD=$(GSPLAT_BUILD) sh scripts/setup_gpu.sh

# every gpu-marked test (skipped by make test)
test-gpu:
	$(BIN)/python -m pytest -q -m gpu $(ARGS)

# every GPU figure in one report: data/08_reports/bench_gpu.{json,md} and docs/benchmarks/bench_gpu.md
bench-gpu:
	$(BIN)/python -m benchmarks.gpu.bench_gpu --docs $(ARGS)

REAL_INDOOR ?= ../shared/data/real_indoor/fungi_room_lod3.spz ../shared/data/real_indoor/wangsha_hall_lod3.spz
# on a host with several GPUs (make setup-gpu first): the release stages over every GPU, 1 GPU vs
# all, one env group per GPU; data/08_reports/multi_gpu.json and its page, docs/benchmarks/bench_multi_gpu.md
bench-multi-gpu:
	$(BIN)/python -m benchmarks.gpu.multi_gpu --real $(REAL_INDOOR) --out data/08_reports $(ARGS)
	$(BIN)/python -m benchmarks.gpu.multi_gpu --docs --out data/08_reports

# the render check's per-ray hits with every backend here (numba; PyTorch on CUDA when present)
# at bench-real's poses (make bench-real first: its data root gives the poses and alignments)
bench-render-check: $(STAMP)
	$(BIN)/python -m benchmarks.captures.render_check_gpu prepare --data data --out data/08_reports/render_check_poses
	$(BIN)/python -m benchmarks.captures.render_check_gpu run data/08_reports/render_check_poses \
		--source fungi_room=$(word 1,$(REAL_INDOOR)) --source wangsha_hall=$(word 2,$(REAL_INDOOR)) \
		--out data/08_reports/render_check_gpu.json $(ARGS)
	$(BIN)/python -m benchmarks.captures.render_check_gpu compare data/08_reports/render_check_gpu.json

dataset: $(STAMP)
	$(BIN)/python -m pipeline $(ARGS)

# lint (ruff) and the import contracts (navcore <- stages <- pipeline; navarena <- navcore) first, then the tests
# the default tests, spread over TEST_WORKERS processes (pytest-xdist, a module per process, the
# modules sharing the session's episode data root on one, the longest units first, the workers'
# OpenMP threads waiting passively: tests/conftest.py; 0: this process): on the 2-core VM, 2 workers
# took 14 min 48 s (2026-12-07; 27 min 52 s before the passive wait and the order)
TEST_WORKERS ?= 2
test: lint
	$(BIN)/python -m pytest -q -n $(TEST_WORKERS) --dist loadfile $(ARGS)

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/lint-imports

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m "slow or not slow" $(ARGS)

bench: bench-spatial bench-episodes bench-eval bench-semantics

# the benchmark pages (docs/benchmarks/bench_*.md) whose inputs changed since they were measured: the hashes of
# the stages they measure (as the pipeline's markers) and the digest of their code (benchmarks/pages.py
# names each page's stages, code and command); exits 1 when one is stale
bench-stale: $(STAMP)
	$(BIN)/python -m benchmarks.pages stale --strict

bench-spatial: $(STAMP)
	$(BIN)/python -m benchmarks.map.spatial --docs $(ARGS)

# the README's tour as a new user meets it: each command's time against the time the README states
# (a scratch folder with its own data/) -> data/08_reports/tour.json, docs/benchmarks/bench_tour.md
bench-tour: $(STAMP)
	$(BIN)/python -m benchmarks.usage.tour --docs $(ARGS)

# the episode dataset of the default scenes: Table-4 style summary, throughput, re-checks
bench-episodes: $(STAMP)
	$(BIN)/python -m benchmarks.dataset.episodes --docs $(ARGS)

# closed-loop figures on this machine (oracle / random on the dataset, env overhead, CPU renderer
# steps/s); merges data/08_reports/eval_gpu.json when a CUDA run (bench-eval-gpu) left one there
bench-eval: $(STAMP)
	$(BIN)/python -m benchmarks.closed_loop.eval --docs $(ARGS)

bench-eval-gpu: $(STAMP)
	$(BIN)/python -m benchmarks.closed_loop.eval --gpu $(ARGS)

# semantic precision (valid-centre rate, recall; 3 corruption levels, ablations, naive baseline) on
# 10 synthetic scenes and seconds per scene; merges data/08_reports/semantics_gpu.json when a CUDA
# run (bench-semantics-gpu) left one there
bench-semantics: $(STAMP)
	$(BIN)/python -m benchmarks.goals.semantics $(ARGS)
	# the lifting on real labelled geometry, where ../shared/data/real_labelled is present
	if [ -d ../shared/data/real_labelled/scannet_scene0000_02 ]; then \
	  $(BIN)/python -m benchmarks.goals.semantics_real --docs --scan ../shared/data/real_labelled/scannet_scene0000_02; \
	  $(BIN)/python -m benchmarks.goals.semantics_detector --docs --scan ../shared/data/real_labelled/scannet_scene0000_02; fi

bench-semantics-gpu: $(STAMP)
	$(BIN)/python -m benchmarks.goals.semantics --gpu $(ARGS)

# the release folder users download, from the finished data root (make dataset first; the same
# ARGS as the dataset was made with, plus release.* keys), e.g. make release ARGS="--version 1.0.0"
release: $(STAMP)
	$(BIN)/navarena release $(ARGS)

# check a release folder as a user does after a download: make verify-release DIR=data/11_releases/navarena-v0.1.0
DIR ?= data/11_releases/navarena-v0.1.0
verify-release: $(STAMP)
	$(BIN)/navarena verify-release $(DIR) $(ARGS)

# a release of the 2,000-scene simulation: time, peak memory, files, bytes, verify-release time and the
# 22 M-episode projection -> data/08_reports/bench_release.{json,md}, docs/benchmarks/bench_release.md
bench-release: $(STAMP)
	$(BIN)/python -m benchmarks.publishing.release --docs $(ARGS)

# evaluate an agent on the dataset, e.g. make eval ARGS="evaluate.agent=depth_reactive"
eval: $(STAMP)
	$(BIN)/python -m pipeline stages=[evaluate] $(ARGS)

# the real indoor scenes of ../shared/data/real_indoor end to end (catalogs/real_indoor.yaml), the
# render-based costmap check, and the realistic synthetic scenes against the mesh
# the generated world against the real captures (issue 82): image statistics of frames at matched camera
# heights and pitches, and a generated-vs-real classifier's held-out accuracy, before (the same scenes without
# synthetic.look, data/realism/before) and after (make dataset's) -> docs/benchmarks/bench_realism.md
# frames need no semantics: the stage named (so a root made with other detector settings is not refused) and off
REALISM_STAGES := stages=[synthesize,ingest,voxelize,align,costmap,screen,episodes,semantics] semantics.enabled=false
bench-realism: dataset
	$(BIN)/python -m pipeline $(REALISM_STAGES) scenes=real_indoor data_root=data/realism/captures
	$(BIN)/python -m pipeline $(REALISM_STAGES) data_root=data/realism/before synthetic.look.enabled=false \
		synthetic.look.ceiling=false synthetic.look.furnish=false
	$(BIN)/python -m benchmarks.captures.realism --generated data --before data/realism/before --real data/realism/captures --docs $(ARGS)

# the costmap of one room at several densities (issue 84): the trained ScanNet 3DGS (make bench-trained-scan,
# a GPU machine) pruned to 50, 25, 12 % and to 81 k, and a SceneSplat-like version, against the scan
# -> data/08_reports/bench_density.json, docs/benchmarks/bench_density.md
bench-density: $(STAMP)
	$(BIN)/python -m benchmarks.captures.density --docs $(ARGS)

bench-real: $(STAMP)
	$(BIN)/python -m benchmarks.captures.real $(ARGS)

# on a CUDA machine (make setup-gpu first): a 3DGS trained with gsplat on views of the real ScanNet
# scan, in the scan's frame -> data/trained_scan/ (model.ply, cameras.json, train.json); bench-real
# then compares its costmap with the scan (benchmarks.captures.scan_truth --model)
SCAN ?= ../shared/data/real_labelled/scannet_scene0000_02
bench-trained-scan:
	$(BIN)/python -m benchmarks.captures.train_on_scan $(SCAN) data/trained_scan $(ARGS)

# scene and region screening: the quality layer against injected blur and holes on realistic
# synthetic scenes, and on the real indoor scenes (their screen stage run first; pictures and the
# sharpness cross-check) -> data/08_reports/screening.json, docs/benchmarks/bench_screening.md
bench-screening: $(STAMP)
	$(BIN)/python -m pipeline stages=[screen] scenes=real_indoor data_root=data/real_indoor
	$(BIN)/python -m benchmarks.captures.screening --real-data data/real_indoor --docs $(ARGS)

# issue 13's proof (about two hours on two cores): storage of the default and real datasets, the
# release cost, the 2,000-scene simulation, the SLURM tests, the CPU renderer (benchmarks/scale/suite.py)
bench-scale: $(STAMP)
	$(BIN)/python -m benchmarks.scale.suite $(ARGS)

# on a CUDA machine: writes data/08_reports/voxelize_gpu.json; bench-spatial merges it (or
# `python -m benchmarks.map.spatial --merge-gpu` folds it into an existing report)
bench-spatial-gpu: $(STAMP)
	$(BIN)/python -m benchmarks.map.voxelize_gpu $(ARGS)

# sharded array job on a batch cluster: make submit SHARDS=64 SCHEDULER=slurm ARGS="scenes=synthetic_large"
# (SUBMIT_FLAGS: more options of pipeline.submit, e.g. "--wait --cpus 4 --mem 16G --queue cpu")
SHARDS ?= 8
SCHEDULER ?= slurm
SUBMIT_FLAGS ?=
submit: $(STAMP)
	$(BIN)/python -m pipeline.submit --shards $(SHARDS) --scheduler $(SCHEDULER) $(SUBMIT_FLAGS) -- $(ARGS)

# issue 14's and 48's proof (tests/faults/suite.py): the fault-injection scenarios, 10,000
# fuzz cases of each input kind, reader layout and agent-server frame type, a run under chaos
# (CHAOS_MINUTES=60: the scale simulation for an hour, about 2 hours in all), then
# data/08_reports/bench_faults.{json,md} and docs/benchmarks/bench_faults.md
CHAOS_MINUTES ?= 5
test-faults: $(STAMP)
	PYTHONPATH=tests $(BIN)/python -m faults.suite --chaos-minutes $(CHAOS_MINUTES) $(ARGS)

# the batch-scheduler tests: a one-node SLURM on this machine (scripts/slurm_localhost.sh, root),
# then make submit (array job, shards, cancel and resubmit) and executor=slurm (dask-jobqueue)
test-slurm: $(STAMP)
	scripts/slurm_localhost.sh
	$(BIN)/python -m pytest -q -m slurm tests/test_slurm.py $(ARGS)

clean:
	rm -rf data/_hydra data/_runs
