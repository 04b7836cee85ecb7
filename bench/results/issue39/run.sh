# One device call of issue 39 item 3 (branches gpu2 and gpu3, asked for as nvidia-h100-x2), run
# from the repo root (main's tree) on the device: bash bench/results/issue39/run.sh RUN [STEP...]
# RUN is the call's carried folder under .whl (gpu2/b, gpu3/b: wheels, warp.so part-01, the
# branch's tree as new.tar; see env.sh). Always: setup from an empty kernel cache; sections 1+7
# at 16,384/65,536 (the branch), main's section 7 against the same section 1; section 30 with
# the cameras on cuda:1 and on cuda:0 with the ticks' RTF. STEPs add, at their place:
#   first    the first service run after setup (section 7 at 16,384), before sections 1+7
#   again    the branch's section 7 once more, after main's (order check)
#   beside   gpu2/check.py: the beside snapshot equals the plain one at 65,536 worlds
#   profile  section 18's profile at 65,536 worlds (packed binary frames), branch then main
# The README beside this file says which call ran with which STEPs (each call ran a copy of
# this script of its own, gpu2/run.sh and gpu3/run.sh, differing only in RUN and these steps).
set -o pipefail
H=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
RUN=$1; shift; STEPS=" $* "
has() { [[ $STEPS == *" $1 "* ]]; }
R=$(pwd)
L=$OUT/log.txt
source "$H/env.sh" ".whl/$RUN" >>$L 2>&1 || { echo "INSTALL FAILED"; tail -5 $L; exit 1; }
nvidia-smi -L | tee -a $L; nproc | tee -a $L
S=/tmp/site; NEW=/tmp/new; T=$OUT/res.tar
keep() { (cd /tmp && tar -rf $T "$@" 2>/dev/null); }
step() { local name=$1 lim=$2; shift 2; local t0=$SECONDS; echo "== $name" >>$L; timeout $lim "$@" >/tmp/$name.log 2>&1; local rc=$?; echo "$name rc=$rc $((SECONDS-t0)) s" | tee -a $L; grep -E "world-steps/s|FAILED|Error|ready in|svc/engine|ratio|RTF|ticks/s|pictures|batches/s|served|beside|snapshot|alone" /tmp/$name.log | tail -40 >>$L; keep $name.log; }
branch() { cd $NEW; export PYTHONPATH=$NEW:$S; }
main() { cd $R; export PYTHONPATH=$R:$S; }
branch
rm -rf ~/.cache/warp
step setup 240 python3 -m service.cli setup --device cuda
if has first; then
  step first 100 python3 -m bench.service_bench --section 7 --device cuda --worlds 16384 --quick --out /tmp/r_first
  keep r_first
fi
step s17 170 python3 -m bench.runner --device cuda --section 1 --section 7 --worlds 16384 --worlds 65536 --quick --out /tmp/r_new
keep r_new
mkdir -p /tmp/r_main /tmp/r_new2 && cp /tmp/r_new/throughput_cuda.json /tmp/r_main/ && cp /tmp/r_new/throughput_cuda.json /tmp/r_new2/
main
step main7 100 python3 -m bench.service_bench --section 7 --device cuda --worlds 16384 --worlds 65536 --quick --out /tmp/r_main
keep r_main
branch
if has again; then
  step new7b 100 python3 -m bench.service_bench --section 7 --device cuda --worlds 16384 --worlds 65536 --quick --out /tmp/r_new2
  keep r_new2
fi
if has beside; then step beside 60 python3 $H/gpu2/check.py 65536; fi
if has profile; then
  P="import json,sys; from bench.tick_profile import profile; r=profile(65536,'cuda:0','binary',4.0,'packed'); print('served', json.dumps({k: r[k] for k in ('engine_ms_per_tick','served_ms_per_tick','served_vs_engine','seconds_per_s','ms_per_call')}))"
  step prof_new 80 python3 -c "$P"
  main
  step prof_main 80 python3 -c "$P"
  branch
fi
export ARMFLEET_BENCH_STREAMS=realtime:8@cuda:1,realtime:8 ARMFLEET_BENCH_FITS=0
step cam 200 python3 -m bench.runner --section 30 --device cuda --worlds 16384 --out /tmp/r_cam
unset ARMFLEET_BENCH_STREAMS ARMFLEET_BENCH_FITS
keep r_cam
echo done | tee -a $L
