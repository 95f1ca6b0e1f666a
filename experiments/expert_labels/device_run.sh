#!/usr/bin/env bash
# The 6D expert's long jobs on the lent 16-core machine, side by side until END seconds: its
# evaluations on the 200 fixed unseen episodes (`evaluate --run planner`: GATE processes) and,
# on the cores left, labels of training objects (`corn-drake label`, one DAgger round).
# Every process writes its own part (rows after each episode: a kill loses at most the episode in
# progress); all parts come back as one xz tarball split under 15 MB.
#
# Here, first: bash ../shared/device/prepare.sh (once), and pack the two libraries:
#   tar -C data --exclude=.coacd_cache --exclude=.lock -cf - library_train library_unseen \
#     | xz -6 > .device/libraries.tar.xz
# With the device tool: carry .device/site_a.tar.xz, .device/site_small.tar.xz, .device/syslib,
# .device/setup.sh, .device/cli.sh, .device/libraries.tar.xz; command
#   LABEL_SEED=<new round's seed> \
#   bash experiments/expert_labels/device_run.sh
# timeout 590. Back here (FILES_AT from the tool's answer):
#   cat FILES_AT/parts.tar.xz.part* | xz -d | tar -C runs -xf -     # runs/device_parts/
#   corn-drake merge-reports runs/device_parts/label_*.rows.jsonl \
#     --report models/labels/full6d/round<N>.json        # its .labels.jsonl.gz beside it
# Settings: END (s from the start, default 560), GATE (processes on gate B, default 0: its 200
# are in), GATE_FROM/GATE_TO (its episode range, default 40..200), LABEL_SEED (default 1),
# LEARNER (a run folder in the checkout; default none: the expert acts), BETA, LABEL_EPISODES
# (per process, default 12). The issue's other evaluations (the at-rest rule, push_turn) have
# their 200 in. Label processes take the cores left of 16.
set -u
T0=$(date +%s)
el() { echo "[$(( $(date +%s) - T0 )) s] $*"; }
bash .device/setup.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONUNBUFFERED=1
export PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/syslib
cd_cli() { python3 -c 'import sys; from corn_drake.cli import main; sys.exit(main())' "$@"; }
mkdir -p data runs/device_parts "$OUT"
[ -d data/library_train ] || tar -C data -xJf .device/libraries.tar.xz
END=${END:-560}; GATE=${GATE:-0}; GATE_FROM=${GATE_FROM:-40}; GATE_TO=${GATE_TO:-200}
LABEL_SEED=${LABEL_SEED:-1}; LABEL_EPISODES=${LABEL_EPISODES:-12}
LEARN=(); [ -n "${LEARNER:-}" ] && LEARN=(--learner "$LEARNER" --beta "${BETA:-0}")
left=$(( END - ($(date +%s) - T0) ))
el "$(nproc) cores; gate B $GATE_FROM..$GATE_TO in $GATE parts; $left s"
# parts NAME COUNT FROM TO [evaluate settings...]: COUNT processes play episodes FROM..TO-1 of
# the expert, each into runs/device_parts/NAME_<first episode>.json.
parts() {
  local name=$1 count=$2 from=$3 to=$4; shift 4
  [ "$count" -gt 0 ] || return 0
  local span=$(( (to - from + count - 1) / count )) p a b
  for p in $(seq 0 $((count - 1))); do
    a=$(( from + p * span )); b=$(( a + span < to ? a + span : to ))
    [ "$a" -lt "$b" ] || continue
    timeout -k 10 $left cd_cli evaluate --run planner --objects data/library_unseen \
      --split unseen --record 0 --episodes-from $a --episodes $b --no-progress "$@" \
      --report runs/device_parts/${name}_$a.json > runs/device_parts/${name}_$a.log 2>&1 &
  done
}
parts gate "$GATE" "$GATE_FROM" "$GATE_TO"
for p in $(seq 0 $((15 - GATE))); do
  a=$(( p * LABEL_EPISODES ))
  timeout -k 10 $left cd_cli label --objects data/library_train --seed $LABEL_SEED \
    --episodes-from $a --episodes $(( a + LABEL_EPISODES )) "${LEARN[@]}" --no-progress \
    --out runs/device_parts/label_$a > runs/device_parts/label_$a.log 2>&1 &
done
wait
el "gate episodes: $(cat runs/device_parts/gate_*.rows.jsonl 2>/dev/null | grep -c '"episode"')"
el "labelled episodes: $(cat runs/device_parts/label_*.rows.jsonl 2>/dev/null | grep -c '"episode"')"
grep -h -i "error\|Traceback" runs/device_parts/*.log | sort | uniq -c | head -5
tar -C runs -cf - device_parts | xz -T16 -6 > /tmp/parts.tar.xz
(cd "$OUT" && split -b 15M /tmp/parts.tar.xz parts.tar.xz.part)
ls -la "$OUT"; el done
