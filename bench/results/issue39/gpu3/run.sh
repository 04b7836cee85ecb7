# Call B (issue 39 item 3, branch gpu3, on nvidia-h100-x2): setup from an empty kernel cache;
# sections 1+7 at 16,384/65,536 (branch gpu3), main's section 7 against the same section 1, the
# branch's section 7 again (order check); cameras on cuda:1 and cuda:0 with the ticks' RTF.
set -o pipefail
R=$(pwd)
L=$OUT/log.txt
source .whl/gpu3/b/env.sh >>$L 2>&1 || { echo "INSTALL FAILED"; tail -5 $L; exit 1; }
nvidia-smi -L | tee -a $L; nproc | tee -a $L
S=/tmp/site; NEW=/tmp/new; T=$OUT/res.tar
keep() { (cd /tmp && tar -rf $T "$@" 2>/dev/null); }
step() { local name=$1 lim=$2; shift 2; local t0=$SECONDS; echo "== $name" >>$L; timeout $lim "$@" >/tmp/$name.log 2>&1; local rc=$?; echo "$name rc=$rc $((SECONDS-t0)) s" | tee -a $L; grep -E "world-steps/s|FAILED|Error|ready in|svc/engine|ratio|RTF|ticks/s|pictures|batches/s|served|alone" /tmp/$name.log | tail -40 >>$L; keep $name.log; }
cd $NEW; export PYTHONPATH=$NEW:$S
rm -rf ~/.cache/warp
step setup 240 python3 -m service.cli setup --device cuda
step s17 170 python3 -m bench.runner --device cuda --section 1 --section 7 --worlds 16384 --worlds 65536 --quick --out /tmp/r_new
keep r_new
mkdir -p /tmp/r_main /tmp/r_new2 && cp /tmp/r_new/throughput_cuda.json /tmp/r_main/ && cp /tmp/r_new/throughput_cuda.json /tmp/r_new2/
cd $R; export PYTHONPATH=$R:$S
step main7 100 python3 -m bench.service_bench --section 7 --device cuda --worlds 16384 --worlds 65536 --quick --out /tmp/r_main
keep r_main
cd $NEW; export PYTHONPATH=$NEW:$S
step new7b 100 python3 -m bench.service_bench --section 7 --device cuda --worlds 16384 --worlds 65536 --quick --out /tmp/r_new2
keep r_new2
export ARMFLEET_BENCH_STREAMS=realtime:8@cuda:1,realtime:8 ARMFLEET_BENCH_FITS=0
step cam 200 python3 -m bench.runner --section 30 --device cuda --worlds 16384 --out /tmp/r_cam
keep r_cam
echo done | tee -a $L
