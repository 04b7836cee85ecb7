# Issue 39 item 3 on one H200 (branch gpu7). Call A, carry [".whl/gpu/a"]:
#   mkdir -p /tmp/parts && cp .whl/gpu/a/* /tmp/parts/
# then calls carrying [".whl/gpu7/b"]: bash .whl/gpu7/b/run.sh STEP...
# STEP: tl:TREE:N (timeline probe, bench/results/issue39/gpu6/tl) or s25:TREE:N (section 25);
# TREE main (git archive of main) or new (of gpu7). Results in $OUT/res.tar, log in $OUT/log.txt.
set -o pipefail
R=$(pwd) B=${B:-$(pwd)/.whl/gpu7/b} S=/tmp/site
L=$OUT/log.txt T=$OUT/res.tar
WARPCACHE=1 . "$R/bench/results/issue39/device_install.sh"  # as it ran then, inline
for t in main new; do rm -rf /tmp/$t && mkdir -p /tmp/$t && tar -xzf $B/$t.tar.gz -C /tmp/$t || exit 1; done
export PYTHONUNBUFFERED=1
cat $B/VERSIONS | tee -a $L; nvidia-smi -L | tee -a $L; echo "install done at $SECONDS s" | tee -a $L
keep() { (cd /tmp && tar -rf $T "$@" 2>/dev/null); }
PROBE=/tmp/new/bench/results/issue39/gpu6/tl/timeline.py
i=0
for s in "$@"; do
  i=$((i+1)); kind=${s%%:*}; rest=${s#*:}; tree=${rest%%:*}; n=${rest#*:}; name=${kind}_${tree}_${n}_$i
  left=$((${CAP:-585} - SECONDS)); [ $left -lt 40 ] && { echo "$name skipped: no time left" | tee -a $L; continue; }
  t0=$SECONDS; echo "== $name" >>$L
  if [ $kind = tl ]; then
    (cd /tmp/$tree && PYTHONPATH=/tmp/$tree:$S timeout $left python3 $PROBE /tmp/$name $n) >/tmp/$name.log 2>&1
  else
    (cd /tmp/$tree && PYTHONPATH=/tmp/$tree:$S timeout $left python3 -m bench.runner --device cuda --section 25 --worlds $n --out /tmp/$name) >/tmp/$name.log 2>&1
  fi
  echo "$name rc=$? $((SECONDS-t0)) s" | tee -a $L
  grep -E "Error|pair|ratio|service|done" /tmp/$name.log | tail -12 >>$L
  tail -c 200000 /tmp/$name.log >/tmp/$name.tail; keep $name.tail $name
done
echo "done at $SECONDS s" | tee -a $L
