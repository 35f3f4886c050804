#!/usr/bin/env bash
# Submit a whole sharded evaluation to SLURM: prepare shards → index merge → run shards → merge + leaderboard,
# each stage starting when the previous one succeeded (afterok).  Settings as in shards.sbatch, plus
# SHARDS [16].  Example:
#
#   DATASET=euvs ROOT=/data/euvs FITS=/data/euvs_fits PACKETS=/scratch/euvs/packets METHOD=setdiff \
#   CHECKPOINT=/scratch/ckpt/setdiff SHARDS=32 bash benchmarks/slurm/submit.sh
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
shards=${SHARDS:-16}
last=$((shards - 1))
submit() { sbatch --parsable --export=ALL "$@"; }
prepare=$(submit --array=0-$last "$here/shards.sbatch" prepare)
index=$(submit --dependency=afterok:$prepare "$here/shards.sbatch" prepare-merge)
run=$(submit --dependency=afterok:$index --array=0-$last "$here/shards.sbatch" run)
merge=$(submit --dependency=afterok:$run "$here/shards.sbatch" run-merge)
echo "submitted: prepare $prepare, index $index, run $run, merge + leaderboard $merge"
