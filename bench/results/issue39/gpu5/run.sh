# Issue 39 item 3 on one H200 (branch gpu5): section 25 (service over engine) with this branch's
# launch-ahead loop at 16,384 worlds, main's at 16,384 on the same machine, this branch's at
# 65,536. As in ../gpu4: two calls on the same warm machine (warp.so is split in two: part-00
# alone fills a call's carry):
#   call A, carry [".whl/gpu/a"]:  mkdir -p /tmp/parts && cp .whl/gpu/a/* /tmp/parts/
#   call B, carry [".whl/gpu5/b"]: bash .whl/gpu5/b/run.sh
#   call C, no carry, right after on the same machine: section 25 at 16,384 again, main first
#   and then this branch (so that each went first once), as `step` below does:
#     for t in main:/work/main br:/tmp/new; do n=${t%%:*}; d=${t#*:}; (cd $d &&
#       PYTHONPATH=$d:/tmp/site timeout 140 python3 -m bench.runner --device cuda --section 25
#       --worlds 16384 --out /tmp/r_${n}16b); done
# .whl/gpu5/b holds ../gpu4's wheels, part-01, warp_lite.zip, zstd and warpcache.tar.zst (the
# kernel cache ../gpu4's first machine had at its end: no setup needed; the branch changes no
# kernel), this script, new.tar.gz (`git archive` of this branch) and VERSIONS. Main is the
# call's repository root (the session's checkout of main).
set -o pipefail
R=$(pwd) B=$(pwd)/.whl/gpu5/b S=/tmp/site NEW=/tmp/new
L=$OUT/log.txt T=$OUT/res.tar
. "$R/bench/results/issue39/device_install.sh"  # as it ran then, inline
rm -rf $NEW && mkdir -p $NEW && tar -xzf $B/new.tar.gz -C $NEW || exit 1
rm -rf ~/.cache/warp && mkdir -p ~/.cache && $Z -d -q -c $B/warpcache.tar.zst | tar -xf - -C ~/.cache || exit 1
export PYTHONUNBUFFERED=1
cat $B/VERSIONS | tee -a $L
nvidia-smi -L | tee -a $L; nproc | tee -a $L; echo "install done at $SECONDS s" | tee -a $L
keep() { (cd /tmp && tar -rf $T "$@" 2>/dev/null); }
# Each step gets at most its limit and what is left of the call's 600 s (less a margin).
step() {
  local name=$1 lim=$2 tree=$3; shift 3; local left=$((580 - SECONDS)); [ $left -lt $lim ] && lim=$left
  [ $lim -lt 20 ] && { echo "$name skipped: no time left" | tee -a $L; return; }
  local t0=$SECONDS; echo "== $name ($tree)" >>$L
  (cd $tree && PYTHONPATH=$tree:$S timeout $lim "$@") >/tmp/$name.log 2>&1; echo "$name rc=$? $((SECONDS-t0)) s" | tee -a $L
  grep -E "FAILED|Error|pair|ratio|worlds " /tmp/$name.log | tail -20 >>$L
  tail -c 300000 /tmp/$name.log >/tmp/$name.tail; keep $name.tail
}
grep -c "launches_ahead" $NEW/service/engines/warp.py $R/service/engines/warp.py | tee -a $L
step br16 200 $NEW python3 -m bench.runner --device cuda --section 25 --worlds 16384 --out /tmp/r_br16
keep r_br16
step main16 200 $R python3 -m bench.runner --device cuda --section 25 --worlds 16384 --out /tmp/r_main16
keep r_main16
step br65 220 $NEW python3 -m bench.runner --device cuda --section 25 --worlds 65536 --out /tmp/r_br65
keep r_br65
echo "done at $SECONDS s" | tee -a $L
