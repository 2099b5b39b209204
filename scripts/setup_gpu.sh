#!/usr/bin/env sh
# make setup-gpu: this project on a CUDA machine, in one command.
#   make setup-gpu                     # online: torch from download.pytorch.org for the driver's CUDA
#   make setup-gpu CUDA=12.8           # choose the CUDA build of torch yourself
#   make setup-gpu WHEELS=/path/wheels # offline: every wheel from that folder (pip --no-index)
#   make setup-gpu GSPLAT_BUILD=f.tgz  # reuse gsplat's kernels compiled on an earlier machine (about 100 s)
# Steps: stop with a clear message on a machine without an NVIDIA GPU; a venv (.venv, seeing the
# system's packages, so that a preinstalled CUDA torch is reused); a CUDA build of torch matching
# the driver unless a matching one is already importable; the project with its gpu, open_vocab and
# test extras (gsplat==1.5.3 pinned); then the ready check (navcore.render.ready), whose first
# render compiles gsplat's CUDA kernels into $VENV/torch_extensions once, for every later run
# (navcore.render points TORCH_EXTENSIONS_DIR there whenever it runs in a venv).
set -eu
PY=${PY:-python3}
VENV=${VENV:-.venv}
BIN="$VENV/bin"

if ! command -v nvidia-smi >/dev/null 2>&1 || ! nvidia-smi -L >/dev/null 2>&1; then
  echo "make setup-gpu: no NVIDIA GPU here (nvidia-smi is missing or lists no GPU). On a CPU machine use" \
       "make setup (CPU torch, the CPU renderer)." >&2
  exit 2
fi
DRIVER_CUDA=$(nvidia-smi | sed -n 's/.*CUDA Version: *\([0-9][0-9]*\.[0-9][0-9]*\).*/\1/p' | head -n 1)
CUDA=${CUDA:-$DRIVER_CUDA}
if [ -z "$CUDA" ]; then
  echo "make setup-gpu: nvidia-smi reports no CUDA version; set it: make setup-gpu CUDA=12.8" >&2
  exit 2
fi
# the newest CUDA build of torch that the driver runs: download.pytorch.org's cuXYZ tags
TAG=""
for t in 130 129 128 126 124 121 118; do
  want=$(echo "$t" | sed 's/\(.*\)\(.\)$/\1.\2/')
  if [ "$(printf '%s\n%s\n' "$want" "$CUDA" | sort -V | head -n 1)" = "$want" ]; then TAG="cu$t"; break; fi
done
[ -n "$TAG" ] || { echo "make setup-gpu: CUDA $CUDA is older than any CUDA build of torch (11.8)" >&2; exit 2; }
echo "GPU: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader | head -n 1); driver CUDA $DRIVER_CUDA; torch build $TAG"

PIP_SRC=""
if [ -n "${WHEELS:-}" ]; then
  [ -d "$WHEELS" ] || { echo "make setup-gpu: WHEELS=$WHEELS is not a folder" >&2; exit 2; }
  PIP_SRC="--no-index --find-links $WHEELS"
fi
test -x "$BIN/python" || "$PY" -m venv --system-site-packages "$VENV"
# a python3 that is itself a venv (an image's /opt/torch/.venv with its CUDA torch): ours sees its
# packages too, after its own (--system-site-packages reaches only the base interpreter's)
PARENT=$("$PY" -c "import sys, sysconfig; print(sysconfig.get_paths()['purelib'] if sys.prefix != sys.base_prefix else '')")
[ -z "$PARENT" ] || "$BIN/python" -c "import pathlib, sys, sysconfig; pathlib.Path(sysconfig.get_paths()['purelib'], 'parent_venv.pth').write_text(sys.argv[1] + chr(10))" "$PARENT"
"$BIN/python" -m pip install -q --upgrade pip $PIP_SRC || true

# keep an importable torch whose CUDA the driver runs; otherwise install the matching build
if "$BIN/python" - "$CUDA" <<'EOF'
import sys
try:
    import torch
except ImportError:
    sys.exit(1)
cuda = torch.version.cuda
ok = cuda is not None and tuple(map(int, cuda.split(".")[:2])) <= tuple(map(int, sys.argv[1].split(".")[:2]))
print(f"torch {torch.__version__} (CUDA {cuda}): {'kept' if ok else 'replaced'}")
sys.exit(0 if ok else 1)
EOF
then :; else
  if [ -n "$PIP_SRC" ]; then
    "$BIN/python" -m pip install -q $PIP_SRC torch
  else
    "$BIN/python" -m pip install -q torch --index-url "https://download.pytorch.org/whl/$TAG"
  fi
fi
if [ -n "$PIP_SRC" ]; then
  # offline: every wheel of the folder as it is, then the project itself, neither resolved (a folder
  # carried to an offline machine holds what that machine lacks); pip check names what is still
  # missing: optional parts (open3d for mesh labels, av for videos, mlcroissant for releases) may be
  "$BIN/python" -m pip install -q --no-index --no-deps "$WHEELS"/*.whl
  "$BIN/python" -m pip install -q --no-index --no-deps --no-build-isolation -e .
  "$BIN/python" -m pip check || echo "make setup-gpu: the requirements above are not in $WHEELS nor installed;" \
    "navarena doctor says what each is for"
  # the pipeline's dependency group is no requirement pip knows of: name what the folder lacked (make dataset,
  # the evaluate stage's results check, releases need them)
  "$BIN/python" -c "from navarena.doctor import pipeline_group; g = pipeline_group(); g and g[1] and print('make setup-gpu: the pipeline group lacks', ', '.join(g[1]), '(add their wheels to $WHEELS)')"
else
  # the library with its gpu extra, plus the pipeline project's dependency groups (pyproject.toml)
  "$BIN/python" -m pip install -q -e ".[gpu,media,open_vocab,pretrained]" --group pipeline --group test
fi
# the checkout's pipeline/ and stages/ on the venv's path (as make setup does)
"$BIN/python" -c "import pathlib, sysconfig; pathlib.Path(sysconfig.get_paths()['purelib'], 'navarena_checkout.pth').write_text(str(pathlib.Path.cwd()) + chr(10))"
# GSPLAT_BUILD=file.tgz: gsplat's compiled kernels from an earlier machine of the same image and
# versions ($VENV/torch_extensions packed with tar czf -C $VENV), so they are not compiled again;
# unpacked after gsplat's install and touched newer than its sources (ninja rebuilds by file times)
if [ -n "${GSPLAT_BUILD:-}" ]; then
  tar xzf "$GSPLAT_BUILD" -C "$VENV" && find "$VENV/torch_extensions" -exec touch {} +
fi
# the optional Yolo-Fastest detector's Darknet reader: OpenCV 5 has none (the default detector's ONNX models need none)
"$BIN/python" -c "import cv2, sys; sys.exit(0 if hasattr(cv2.dnn, 'readNetFromDarknet') else 1)" 2>/dev/null || \
  echo "make setup-gpu: the OpenCV here has no Darknet reader (OpenCV 5): the default detector runs, the optional" \
    "semantics.detector.model=yolo_fastest_1.1_coco needs 'opencv-python-headless>=4.8,<5'" >&2
mkdir -p data/08_reports
"$BIN/python" -m navcore.render.ready --json data/08_reports/gpu_ready.json
touch "$VENV/.installed-gpu"
