#!/usr/bin/env bash
# Quality of SetDiff's speed options (issue 55) on one embedded benchmark, against the shipped model they
# come from, with the toolkit's own commands:
#   student       the guidance-distilled one-pass student (packaged config <teacher>_student: one UNet pass
#                 instead of the teacher's two CFG branches);
#   view0         the teacher re-trained with per-view set attention at level 0 (benchmarks/configs/<teacher>_view0);
#   knn0          the same with the 16 nearest reference tokens in 3D (<teacher>_knn0);
#   finetune      the control of view0 / knn0: the same fine-tune with full set attention (<teacher>_finetune);
#   student_view0 the student with per-view level-0 attention (both options: <teacher>_student_view0);
#   one_pass      the teacher itself run in one pass (guidance 1): what the student is for.
# Each is trained from the shipped teacher (students: distilled; view0 / knn0: fine-tuned on the ground truth,
# [train] init_from), exported, run on the test split and compared with the teacher (`compare`: paired
# gains, intervals resampled by scene).
#
#   bash benchmarks/speed_options.sh BENCHMARK PACKETS WORK [OPTION ...]
#
# BENCHMARK: driving (teacher tiny_setdiff; PACKETS from benchmarks/train_shipped_models.sh's data steps) or
# sparse (tiny_setdiff_sparse; PACKETS from benchmarks/train_sparse_models.sh STAGE=data).  WORK receives
# checkpoints, exported models, runs and comparisons.  OPTION: which of the above (default all, in that
# order); two invocations with different options may run side by side (one torch thread each).  Every step
# resumes.  The quality table in docs/performance.md is made from WORK/compare/*.md.
set -euo pipefail
benchmark=$1
packets=$2
work=$3
shift 3
options=("$@")
[[ ${#options[@]} -eq 0 ]] && options=(student view0 knn0 finetune student_view0 one_pass)
export SETDIFF_THREADS=${SETDIFF_THREADS:-1}
bench="python3 -m setdiff_bench"
here=$(dirname "$0")
case $benchmark in
    driving) teacher=tiny_setdiff ;;
    sparse) teacher=tiny_setdiff_sparse ;;
    *) echo "speed_options.sh: BENCHMARK must be driving or sparse, got '$benchmark'" >&2; exit 2 ;;
esac
run_test() {  # run_test NAME RUN_OPTIONS...: enhance and score the test split
    local name=$1
    shift
    $bench run "$@" --packets "$packets" --split test --out "$work/runs/$name" --name "$name" \
        --metrics psnr,ssim,lpips --warp off --no-progress
}
score() {  # score NAME RUN_OPTIONS...: run_test, then compare with the teacher (scored once, under a lock)
    run_test "$@"
    until mkdir "$work/teacher.lock" 2>/dev/null; do sleep 10; done
    [[ -f $work/runs/teacher/metrics.parquet ]] || run_test teacher --method setdiff --checkpoint "$teacher" \
        || { rmdir "$work/teacher.lock"; exit 1; }
    rmdir "$work/teacher.lock"
    $bench compare "$work/runs/$1" "$work/runs/teacher" --out "$work/compare" --metrics psnr,ssim,lpips
}
mkdir -p "$work"
for option in "${options[@]}"; do
    case $option in
        student) config=${teacher}_student ;;
        view0 | knn0 | finetune | student_view0) config=$here/configs/${teacher}_$option.toml ;;
        one_pass)
            score one_pass --method setdiff --checkpoint "$teacher" -o guidance_scale=1
            continue
            ;;
        *) echo "speed_options.sh: unknown option '$option'" >&2; exit 2 ;;
    esac
    $bench train --config "$config" --packets "$packets" --out "$work/ckpt/$option" --no-progress
    $bench weights export "$work/ckpt/$option" --name "${teacher}_$option" --to "$work/weights"
    score "$option" --method setdiff --checkpoint "$work/weights/${teacher}_$option"
done
# the restricted fine-tunes against the control fine-tune: what the restriction alone costs
for option in view0 knn0; do
    if [[ -f $work/runs/$option/metrics.parquet && -f $work/runs/finetune/metrics.parquet ]]; then
        $bench compare "$work/runs/$option" "$work/runs/finetune" --out "$work/compare" --metrics psnr,ssim,lpips
    fi
done
