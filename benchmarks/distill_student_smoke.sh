#!/usr/bin/env bash
# Smoke training of the guidance-distilled one-pass student (issue 55, packaged config tiny_setdiff_student)
# from the shipped tiny_setdiff (geometry CFG 1.5), on two of the driving benchmark's training scenes (seed 0,
# indices 0 and 1 of the shipped recipe) for 150 steps, scored on one of its test scenes (index 2) against
# the teacher with CFG and the teacher run in one pass (guidance 1), with `compare`'s paired intervals.
#
#   bash benchmarks/distill_student_smoke.sh [WORK_DIR]
#
# Measured on the shared 2-core machine (load average 10-13 from other jobs), 2026-11-28, one torch thread:
# synth 18 min (3 scenes), prepare 3.2 min (43 packets), train 150 steps 22 min (about 6.7 s per step: the
# teacher's two-branch pass plus the student's forward and backward), each run 3-4 min.  Every step resumes.
set -euo pipefail
work=${1:-runs/distill_smoke}
export SETDIFF_THREADS=${SETDIFF_THREADS:-1}
bench="python3 -m setdiff_bench"
$bench synth --out "$work/scenes" --preset default --seed 0 --indices 0,1,2 --jobs 1 --no-progress
$bench prepare synthetic --root "$work/scenes" --fits "$work/scenes" --out "$work/packets" --split all \
    --test-scene scene_0000_02 --workers 1 --no-progress
$bench train --config tiny_setdiff_student --packets "$work/packets" --out "$work/ckpt" --steps 150 --no-progress
$bench weights export "$work/ckpt" --name tiny_setdiff_student --to "$work/weights"
for arm in identity teacher teacher_one_pass student; do
    case $arm in
        identity) opts=(--method identity) ;;
        teacher) opts=(--method setdiff --checkpoint tiny_setdiff) ;;
        teacher_one_pass) opts=(--method setdiff --checkpoint tiny_setdiff -o guidance_scale=1) ;;
        student) opts=(--method setdiff --checkpoint "$work/weights/tiny_setdiff_student") ;;
    esac
    $bench run "${opts[@]}" --packets "$work/packets" --split test --out "$work/runs/$arm" \
        --metrics psnr,ssim,lpips --warp off --no-progress
done
$bench compare "$work/runs/student" "$work/runs/teacher" --out "$work/compare" --metrics psnr,ssim,lpips
$bench compare "$work/runs/teacher_one_pass" "$work/runs/teacher" --out "$work/compare" --metrics psnr,ssim,lpips
