#!/usr/bin/env bash
# Outcome data on the lent 16-core machine (experiments/primitive_policy/LOG.md, item 38): a larger
# procedural training library (seed 1, the train split of an 800-object build, 64 drops per
# object: what 210 s of 16 processes build, 190 objects there) and lookahead outcome data on it
# (16 processes of `corn-drake collect-outcomes` with the shipped push_turn policy, at rest,
# settling 10 periods, until 485 s: 181 episodes on 161 objects there); both come back packed
# in parts under 15 MB. This is how the shipped full6d_outcome's runs/big_collect was made.
# After shared/device/prepare.sh, from the project root, with the device tool: carry
# .device/site_a.tar.xz, .device/site_small.tar.xz, .device/syslib, .device/setup.sh,
# .device/cli.sh and this script, command
# `bash experiments/primitive_outcomes/device_collect.sh`, timeout 590 s. Then here:
#   cat FILES_AT/lib.tar.xz.part* | xz -d | tar -C data -xf -      # data/library_big
#   cat FILES_AT/col.tar.xz.part* | xz -d | tar -C runs -xf -      # runs/big_collect
# Each process takes 3 x (objects / 16) episodes from its own start, so the first pass covers
# every object once; episode k runs on object k mod N with seed 5000 + k. OBJ_S and COL_END
# (seconds from the start) bound the two phases; a later call with other library seeds adds
# objects.
set -u
T0=$(date +%s)
el() { echo "[$(( $(date +%s) - T0 )) s] $*"; }
bash .device/setup.sh
export OMP_NUM_THREADS=1 MKL_NUM_THREADS=1 PYTHONUNBUFFERED=1
export PYTHONPATH=/tmp/site:$PWD LD_LIBRARY_PATH=/tmp/syslib
LIB=data/library_big; COL=runs/big_collect
OBJ_S=${OBJ_S:-210}; COL_END=${COL_END:-485}
el "cores $(nproc)"
mkdir -p $COL $OUT
timeout -k 15 $OBJ_S python3 -c 'import sys; from corn_drake.cli import main; sys.exit(main())' \
  objects --num-objects 800 --seed 1 --split train --drops 64 --workers 16 --out $LIB --no-progress \
  > $OUT/objects.log 2>&1
el "objects rc=$?"; tail -3 $OUT/objects.log
N=$(python3 -c "from corn_drake.assets.library import list_objects; print(len(list_objects('$LIB','train')))")
PER=$(( (N + 15) / 16 )); left=$(( COL_END - ($(date +%s) - T0) ))
el "train objects $N, $PER per process, $left s of collection"
for p in $(seq 0 15); do
  timeout -k 10 $left python3 -c 'import sys; from corn_drake.cli import main; sys.exit(main())' \
    collect-outcomes models/weights/push_turn_primitive --objects $LIB --at-rest \
    --episodes $((3*PER)) --start $((p*3*PER)) --chunk 1 --random-motions 1 --settle-steps 10 \
    --out $COL > $COL/log_p$p.txt 2>&1 &
done
wait
el "collected $(ls $COL/*.npz | wc -l) episodes"; tail -2 $COL/log_p0.txt
cat $COL/log_p*.txt | grep '^{' > $OUT/collect_outcomes.jsonl
grep -h -i "error\|Traceback" $COL/log_p*.txt | sort | uniq -c | head -5
tar -C data --exclude=.coacd_cache --exclude=.lock -cf - library_big | xz -T16 -6 > /tmp/lib.tar.xz
tar -C runs -cf - big_collect | xz -T16 -6 > /tmp/col.tar.xz
(cd $OUT && split -b 15M /tmp/lib.tar.xz lib.tar.xz.part && split -b 15M /tmp/col.tar.xz col.tar.xz.part)
ls -la $OUT; el done
