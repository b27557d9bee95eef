#!/bin/bash
# Alternated rounds: main (tree MAIN_SRC), V (branch), E (either test) on tilted-stack and
# double-domino, 3 solvers; one JSON row per run (run_candidates.py).  usage: timing.sh ROUNDS
MAIN_SRC=${MAIN_SRC:-/tmp/cfp/src}; BR=$(cd "$(dirname "$0")/../../../src" && pwd)
cd "$(dirname "$0")"
for r in $(seq 1 "$1"); do
  PYTHONPATH=$MAIN_SRC python run_candidates.py main-r$r CLARABEL,OSQP,PIQP tilted-stack,double-domino
  CAND=V PYTHONPATH=$BR python run_candidates.py V-r$r CLARABEL,OSQP,PIQP tilted-stack,double-domino
  CAND=E PYTHONPATH=$BR python run_candidates.py E-r$r CLARABEL,OSQP,PIQP tilted-stack,double-domino
done
