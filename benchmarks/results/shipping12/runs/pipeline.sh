#!/bin/bash
# session 12 pipeline: evals on set 22 + houses 6040-6059, then the matched default-size control Dm
cd /work/wt/s12
PY="/work/main/.venv/bin/python"
export PYTHONPATH=.
C="noise_0.05 noise_0.10 offset_5cm_5deg offset_10cm_10deg bright_0.6 bright_1.5 colour_cast left_darker wall_retextured furniture_moved floor_recoloured box_on_path box_removed box_beside_path box_after_turn moving_obstacle"
O=/work/dev12/out
ev() {
  echo "$(date +%T) eval $1 start"
  $PY -m vtr.cli eval --suite conditions --routes sim2d/routes/heldout22 --conditions $C --seeds 0 1 --controllers after --suite-models fp32 --workers 2 --model $2 --json $O/$1_set22.json > $O/$1_set22.log 2>&1
  $PY -m vtr.cli eval --houses 6040:6060 --routes-per-house 1 --seeds 0 1 --workers 2 --model $2 --json $O/$1_h6040.json > $O/$1_h6040.log 2>&1
  echo "$(date +%T) eval $1 done"
}
ev S models/velocitynet.onnx
ev P0 /work/dev12/models/gpu2_paper_s0_floors/velocitynet.onnx
ev P1 /work/dev12/models/gpu2_paper_s1_floors/velocitynet.onnx
echo "$(date +%T) collect start"
$PY -m vtr.cli collect --houses 40 --frames-per-house 2000 --include-house house --include-house-frames 10000 --appearances 4 --seed 0 --out /work/dev12/data/recipe --workers 2 --no-progress > $O/collect.log 2>&1
echo "$(date +%T) collect done rc $?"
STD=rgb8_hwc_to_float32_nchw_div255_channel_standardised
R=/work/dev12/dm
prev=""
for st in "a 525 1e-3" "b 400 3e-4" "c 150 3e-4" "floors 1550 1e-4"; do
  set -- $st
  extra=""; [ "$1" = floors ] && extra="--appearance-swap 0.5 --w-consistency 0.3"
  init=""; [ -n "$prev" ] && init="--init $prev/model.pt"
  echo "$(date +%T) train Dm $1 start"
  $PY -m vtr.cli train velocitynet --augment --preprocessing $STD --viewnet models/viewnet.pt --data /work/dev12/data/recipe --out $R/dm_$1 --seed 0 --lr $3 $extra --steps $2 --batch-size 64 --preset default --val-every 100000 --allow-no-gain --device cpu --threads 2 $init > $O/dm_$1.log 2>&1 || { echo "Dm $1 failed"; exit 1; }
  prev=$R/dm_$1
done
echo "$(date +%T) train Dm done"
$PY -m vtr.cli export --checkpoint $R/dm_floors/model.pt --out /work/dev12/models/dm/velocitynet.onnx > $O/dm_export.log 2>&1
ev Dm /work/dev12/models/dm/velocitynet.onnx
ev D /work/dev12/models/gpu1_default_s0_floors/velocitynet.onnx
echo "$(date +%T) all done"
