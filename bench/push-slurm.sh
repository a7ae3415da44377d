#!/usr/bin/env bash
# The push-recovery grid as a Slurm job array (docs/policy.md):
#   python3 bench/push.py jobs --controllers stand,capture,mlp --trials 20 > jobs.txt
#   sbatch --array=1-$(wc -l < jobs.txt)%64 bench/push-slurm.sh jobs.txt results/
#   python3 bench/push.py merge results/ --out push.json   # after the array
#SBATCH --job-name=pushstep-push
#SBATCH --cpus-per-task=1
#SBATCH --time=00:05:00
set -euo pipefail
spec=$(sed -n "${SLURM_ARRAY_TASK_ID}p" "$1")
exec python3 "$(dirname "$0")/push.py" trial "$spec" --out "$2"
