#!/usr/bin/env bash
# The "stable at any press" benchmark: palpate's integrators and MuJoCo 4.0 `discrete` on the protocol
# case at 0.2, 1, 2 and 5 N, one run at a time, in one session (BENCHMARKS.md, "Stable at any press").
#   bash bench/press.sh [PEERS_PYTHON=/work/peers-venv/bin/python] > out/press.jsonl
# Each line is one JSON object: palpate's from `palpate bench protocol --json` (quasi-Newton default with
# rel_L2_vs_newton; linearised and Newton for reference), MuJoCo's from bench/mujoco_force.py.
set -u
cd "$(dirname "$0")/.."
PEER=${1:-/work/peers-venv/bin/python}
M=${PALPATE_SHARED:-../shared}/bench/meshes
P=".venv/bin/python -m palpate bench protocol"
run() { timeout 1800 "$@" || echo "{\"failed\": \"$*\"}"; }
for F in 0.2 1 2 5; do
  run $P $M/lv_1350.msh --force $F --json
  run $P $M/lv_1350.msh --force $F --json --integrator linearised --newton off
  [ -x "$PEER" ] && run "$PEER" bench/mujoco_force.py --mesh 1350 --force $F
done
for F in 0.2 5; do
  run $P $M/lv_190.msh --force $F --json
  run $P ellipsoid_192 --force $F --json
  [ -x "$PEER" ] && run "$PEER" bench/mujoco_force.py --mesh 190 --force $F
done
for F in 0.2 2; do
  run $P $M/lv_10k.msh --force $F --json --newton off
  [ -x "$PEER" ] && run "$PEER" bench/mujoco_force.py --mesh 10k --force $F --max-wall 60
done
run $P $M/lv_50k.msh --force 2 --json --newton off --steps 200
[ -x "$PEER" ] && run "$PEER" bench/mujoco_force.py --mesh 50k --force 2 --steps 200 --max-wall 90
