#!/usr/bin/env bash
# A short soak in make test (tools/soak.py; `make soak` runs the long one):
# 40,000 ticks in lockstep among the crowd with a fault every 8 s, each
# recovered: the same checks as the long soak, but with so few faults one
# hold a loaded host causes would be a tenth of them: half must be judged.
# About 10 s.
set -uo pipefail
cd "$(dirname "$0")/.."
exec python3 tools/soak.py --ticks 40000 --seed 2 --min-judged 0.5 --work build/soak-short
