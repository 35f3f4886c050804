#!/usr/bin/env bash
# Issue 41's scientific check: can an enhancer for lane shifts be trained without multi-lane data?
#
# Tiny SetDiff and tiny DiFix trained on training pairs made from the driving benchmark's lane-0 captures
# alone (`prepare --pairs sparse:4,underfit:0.5`: degraded 3DGS fits of the recorded frames, their renders
# paired with the recorded frames), two training seeds each, then scored beside the shipped models (trained
# on the lane-shift pairs) on the same test targets: the test scenes' lane shifts and held-out frames.
#   1. `synth` of the 14 scenes the shipped models come from (train_shipped_models.sh: preset default,
#      seed 0, scenes _02, _04 and _07 declared test scenes);
#   2. `prepare synthetic --split test`: the test scenes' protocol packets (lane shifts with ground truth);
#   3. `prepare synthetic --split train --pairs sparse:4,underfit:0.5 --fit --fit-preset default`: the 11
#      training scenes' recipe packets, each recipe fit made as the generator made the scene's own fit,
#      except for what the recipe changes (frames seen, iterations);
#   4. `train` of tiny_setdiff and tiny_difix, seeds 0 and 1, on the recipe packets only (2250 steps, one
#      torch thread each, two side by side), exported as the shipped models are (`--average 2`, SetDiff at
#      geometry CFG 1.5);
#   5. `run` of identity, the shipped tiny_setdiff / tiny_difix and the four recipe models on the test packets;
#   6. `benchmarks/model_domains.py`: each model's means and its paired difference to the raw render with a
#      scene-bootstrap interval, all groups and lane+2, into benchmarks/results/recipe_pairs.json.
#
#   bash benchmarks/train_recipe_models.sh [WORK_DIR]
#
# WORK_DIR defaults to runs/recipe.  Every step resumes when the script is run again.  STAGE=data stops
# after the packets.  For a smoke run of the whole chain: PRESET=tiny SCENES=3 STEPS=4 TEST_SCENES=scene_0000_02
# (the tiny preset's scenes are not the shipped models' data, so only the commands are exercised).
set -euo pipefail
work=${1:-runs/recipe}
preset=${PRESET:-default}
scenes=${SCENES:-14}
steps=${STEPS:-2250}
stage=${STAGE:-all}
export SETDIFF_THREADS=${SETDIFF_THREADS:-1}
bench="python3 -m setdiff_bench"
test_scenes=()
for scene in ${TEST_SCENES:-scene_0000_02 scene_0000_04 scene_0000_07}; do test_scenes+=(--test-scene "$scene"); done
mkdir -p "$work/logs"

$bench synth --out "$work/scenes" --preset "$preset" --seed 0 --scenes "$scenes" --jobs 2 --no-progress
$bench prepare synthetic --root "$work/scenes" --fits "$work/scenes" --out "$work/packets" --split test \
    "${test_scenes[@]}" --workers 2 --no-progress
$bench prepare synthetic --root "$work/scenes" --fit --fit-preset "$preset" --out "$work/pairs" --split train \
    "${test_scenes[@]}" --pairs sparse:4,underfit:0.5 --workers 2 --no-progress
[[ $stage == data ]] && exit 0

train() {  # train MODEL SEED: one training, its log in WORK_DIR/logs
    $bench train --config "tiny_$1" --seed "$2" --packets "$work/pairs" --out "$work/ckpt/$1_seed$2" \
        --steps "$steps" --no-progress > "$work/logs/$1_seed$2.log" 2>&1
}
# two lanes of one thread each, about an hour apiece for the default preset (SetDiff ~43 min, DiFix ~16 min)
(train setdiff 0 && train difix 1) &
first=$!
(train difix 0 && train setdiff 1) &
second=$!
wait $first
wait $second

models=(--run driving:tiny_setdiff="$work/runs/tiny_setdiff" --run driving:tiny_difix="$work/runs/tiny_difix")
run() {  # run METHOD NAME [CHECKPOINT]: score one model on the test packets
    $bench run --method "$1" --packets "$work/packets" --split test --out "$work/runs/$2" \
        ${3:+--checkpoint "$3"} --no-progress
}
run identity identity
run setdiff tiny_setdiff tiny_setdiff
run difix tiny_difix tiny_difix
for seed in 0 1; do
    for model in setdiff difix; do
        name="recipe_${model}_seed$seed"
        cfg=()
        [[ $model == setdiff ]] && cfg=(--guidance-scale 1.5)
        $bench weights export "$work/ckpt/${model}_seed$seed" --name "$name" --to "$work/weights" --average 2 "${cfg[@]}"
        run "$model" "$name" "$work/weights/$name"
        models+=(--run "driving:$name=$work/runs/$name")
    done
done
python3 "$(dirname "$0")/model_domains.py" --benchmark driving="$work/runs/identity" "${models[@]}" \
    --out "${OUT_JSON:-benchmarks/results/recipe_pairs.json}" --issue 41 \
    --question "can an enhancer for lane shifts be trained without multi-lane data? models trained on lane-0 recipe pairs (sparse:4, underfit:0.5) against the shipped models (lane-shift pairs), on the same test targets, each against the raw render"
