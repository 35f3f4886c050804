#!/usr/bin/env bash
# Regenerate the models shipped in setdiff_bench/models/setdiff/weights/ with the toolkit's own commands:
# the default synthetic preset's six scenes (seed 0), their packets, then tiny SetDiff and tiny DiFix trained on
# the four training scenes (scene_0000_00, _01, _03, _05; the demo evaluates on _02 and _04), exported with their
# manifests.  The tiny autoencoder both freeze is shipped too; its own command is in its manifest.
#
#   bash benchmarks/train_shipped_models.sh [WORK_DIR] [EXPORT_DIR]
#
# WORK_DIR (default runs/shipped) receives scenes, packets and training runs; EXPORT_DIR (default
# WORK_DIR/weights) the exported model folders — pass setdiff_bench/models/setdiff/weights to replace the shipped
# ones.  Every step resumes when the script is run again.  On 2 CPU cores: about 20 minutes of scenes and
# packets, then the two trainings side by side, one torch thread each (SetDiff about 3 s per step, DiFix
# about 2.5 s per step when they have the machine to themselves).  The same machine and thread count give
# byte-identical weights; see README "Reproducibility" for what differs elsewhere.
set -euo pipefail
work=${1:-runs/shipped}
export_dir=${2:-$work/weights}
export SETDIFF_THREADS=${SETDIFF_THREADS:-1}
bench="python3 -m setdiff_bench"
steps=1500

$bench synth --out "$work/scenes" --preset default --seed 0 --jobs 2 --no-progress
$bench prepare synthetic --root "$work/scenes" --fits "$work/scenes" --out "$work/packets" --split all --workers 2 --no-progress
$bench train --config tiny_setdiff --packets "$work/packets" --out "$work/ckpt/setdiff" --steps $steps --no-progress &
setdiff=$!
$bench train --config tiny_difix --packets "$work/packets" --out "$work/ckpt/difix" --steps $steps --no-progress &
difix=$!
wait $setdiff
wait $difix
$bench weights export "$work/ckpt/setdiff" --name tiny_setdiff --to "$export_dir"
$bench weights export "$work/ckpt/difix" --name tiny_difix --to "$export_dir"
