#!/usr/bin/env sh
# The learned baselines on a GPU machine (docs/evaluation.md, "Baselines"), in phases:
#   sh benchmarks/baselines/run_gpu.sh data          # the generated scenes: SCENES (160) PointNav scenes,
#                                                    # 10 % held out for test (eval_zeroshot), 5 % val_unseen
#   sh benchmarks/baselines/run_gpu.sh train ROUNDS  # navarena train up to ROUNDS (resumes a finished round)
#   sh benchmarks/baselines/run_gpu.sh eval          # ships the run as pointnav_bc, then eval_zeroshot at
#                                                    # 640 x 480 for it and the reference agents, one GPU each
# make setup-gpu first (WHEELS=dir offline). Outputs: $ROOT (data root), $RUN (training run),
# $EVAL/<agent>_<protocol>/summary.json.
set -eu
set -f  # Hydra's list overrides are not file patterns
ROOT=${ROOT:-data/baselines}
SCENES=${SCENES:-160}
RUN=${RUN:-data/runs/pointnav_bc}
EVAL=${EVAL:-data/baseline_eval}
PY=${PY:-.venv/bin/python}
DATA="data_root=$ROOT scenes.count=$SCENES task=[pointnav] semantics.enabled=false episodes.scene_splits.test=0.1 executor.dashboard=false"
case "${1:-}" in
  data)
    $PY -m pipeline $DATA stages=[episodes] executor.n_workers=${WORKERS:-60} ;;
  train)
    # navarena train's defaults are the reference run's settings
    $PY -m navarena train "$ROOT" --out "$RUN" --resume --rounds "${2:-4}" --workers "${TRAIN_WORKERS:-16}" ;;
  eval)
    # the zero-shot set is drawn by the evaluate stage (from the test split's held-out scenes)
    $PY -m pipeline $DATA stages=[evaluate] evaluate.split=eval_zeroshot evaluate.tasks=[pointnav] \
      evaluate.agent=oracle evaluate.render=false > /dev/null
    $PY -m benchmarks.baselines.cards ship "$RUN" pointnav_bc
    mkdir -p "$EVAL"
    n=$($PY -c "import torch; print(max(1, torch.cuda.device_count()))")
    i=0
    for spec in pointnav_bc:distance pointnav_bc:explicit_stop depth_reactive:distance random:distance oracle:distance; do
      agent=${spec%%:*}; proto=${spec##*:}
      CUDA_VISIBLE_DEVICES=$((i % n)) $PY -m navarena eval "$ROOT" --split eval_zeroshot --tasks pointnav \
        --agent "$agent" --protocol "$proto" --batch-slots 32 --width 640 --height 480 --quiet \
        --out "$EVAL/${agent}_$proto" > "$EVAL/${agent}_$proto.log" 2>&1 &
      i=$((i + 1))
    done
    wait
    tail -n 12 "$EVAL"/*.log ;;
  *)
    echo "usage: sh benchmarks/baselines/run_gpu.sh data | train ROUNDS | eval" >&2; exit 2 ;;
esac
