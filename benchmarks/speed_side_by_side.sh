#!/bin/sh
# The loop's speed against a baseline checkout, every bench alternating the two in one
# run (the machine's speed drifts between days and with the other jobs on it).
#   sh benchmarks/speed_side_by_side.sh BASELINE_CHECKOUT NEW_CHECKOUT DEMO_DB
# BASELINE: e.g. `git worktree add --detach ../baseline 222c262`; DEMO_DB: a database
# written by the BASELINE's `study demo` (for the participant fit; the new version
# upgrades a copy of it). Results in benchmarks/results/.
set -e
B=$1; N=$2; DB=$3; R=benchmarks/results
nice -n 10 python benchmarks/loop_side_by_side.py "$B" "$N" --rounds 3 \
  --out $R/loop_profile.json -- --trials 4 --calls 100000
nice -n 10 python benchmarks/loop_side_by_side.py "$B" "$N" --rounds 3 --bench loop_speed.py \
  --out $R/loop_speed_long.json -- --trials 8 --max-s 180
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 5 \
  --json-key speed.realtime_factor_median --out $R/loop_bench_lcca_quick.json -- \
  'study bench lcca --quick --json {tmp}/out.json --out {tmp}'
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 3 \
  --out $R/demo_quick_side_by_side.json -- 'study demo --quick --out {tmp}/demo'
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 3 \
  --out $R/demo_side_by_side.json -- 'study demo --out {tmp}/demo'
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 2 \
  --json-key runs.0.units_per_hour --out $R/campaign_side_by_side.json -- \
  'study bench campaign --replicates 4 --group-size 3 --workers 2 --json {tmp}/out.json'
# the fit reads a fresh copy of DEMO_DB per run, each checkout its own, the new one's
# upgraded beforehand (a shared file upgraded by the new version stops the baseline)
F=$(mktemp -d); cp "$DB" "$F/baseline.db"; cp "$DB" "$F/new.db"
PYTHONPATH="$N" study db upgrade --db "$F/new.db"
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 2 \
  --out $R/participant_fit_side_by_side.json -- \
  "if [ {checkout} = $B ]; then cp $F/baseline.db {tmp}/demo.db; else cp $F/new.db {tmp}/demo.db; fi && study participants fit --db {tmp}/demo.db --out {tmp}/model.json --design 32 --repeats 2 --check 4 --bootstrap 20"
# the same with the fit's default settings (320 settings x 2 repeats, 24 checks, 100
# bootstraps: what a lab waits for), two rounds
nice -n 10 python benchmarks/command_side_by_side.py "$B" "$N" --rounds 2 \
  --out $R/participant_fit_default_side_by_side.json -- \
  "if [ {checkout} = $B ]; then cp $F/baseline.db {tmp}/demo.db; else cp $F/new.db {tmp}/demo.db; fi && study participants fit --db {tmp}/demo.db --out {tmp}/model.json"
PYTHONPATH="$N" nice -n 10 python benchmarks/analyze_vs_r.py --db "$DB" --rounds 5 \
  --out $R/analyze_vs_r.json
