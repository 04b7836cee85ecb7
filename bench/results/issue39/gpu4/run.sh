# Issue 39 items 1 and 3 on one H200 (branch gpu4). Each session: two calls on the same warm
# machine, as in ../gpu2 and ../gpu3 (warp.so is split in two: part-00 alone fills a call's carry):
#   call A, carry [".whl/gpu/a"]:  mkdir -p /tmp/parts && cp .whl/gpu/a/* /tmp/parts/
#   call B, carry [".whl/gpu4/b"]: bash .whl/gpu4/b/run.sh b   (session 2: ... run.sh c)
# .whl/gpu4/b holds ../gpu3's wheels, part-01, warp_lite.zip and zstd (hard links), new.tar
# (`git archive` of this branch) and, for session 2, warpcache.tar.zst (the kernel cache session
# 1's machine had at its end: no setup needed).
# b: `armfleet setup --device cuda` from an empty kernel cache, section 24 (Newton vs CG, speed
#    and fidelity) at 16,384 and 65,536 worlds, the solver it finds faster set in the tree's
#    physics.py, section 25 (service over engine, 3 alternating pairs, 10 s windows) at 16,384,
#    section 18's profile of a served tick at 16,384.
# c: section 25 at 16,384 with the sim thread's GIL wait at 0.1 ms (pace.SWITCH_INTERVAL_S), then
#    as committed (0.5 ms), then section 25 at 65,536 as committed.
set -o pipefail
R=$(pwd) B=$(pwd)/.whl/gpu4/b S=/tmp/site NEW=/tmp/new
L=$OUT/log.txt T=$OUT/res.tar
. "$R/bench/results/issue39/device_install.sh"  # as it ran then, inline
rm -rf $NEW && mkdir -p $NEW && tar -xf $B/new.tar -C $NEW
export PYTHONUNBUFFERED=1 PYTHONPATH=$NEW:$S
cd $NEW
nvidia-smi -L | tee -a $L; nproc | tee -a $L; echo "install done at $SECONDS s" | tee -a $L
keep() { (cd /tmp && tar -rf $T "$@" 2>/dev/null); }
# Each step gets at most its limit and what is left of the call's 600 s (less a margin).
step() {
  local name=$1 lim=$2; shift 2; local left=$((580 - SECONDS)); [ $left -lt $lim ] && lim=$left
  [ $lim -lt 20 ] && { echo "$name skipped: no time left" | tee -a $L; return; }
  local t0=$SECONDS; echo "== $name" >>$L
  timeout $lim "$@" >/tmp/$name.log 2>&1; echo "$name rc=$? $((SECONDS-t0)) s" | tee -a $L
  grep -E "world-steps|fidelity|FAILED|Error|ready in|pair|ratio|solver|worlds |passes|FAILS|served" /tmp/$name.log | tail -40 >>$L
  tail -c 300000 /tmp/$name.log >/tmp/$name.tail; keep $name.tail  # CG's warnings: 744 MB in b
}
case $1 in
b)
rm -rf ~/.cache/warp
step setup 200 python3 -m service.cli setup --device cuda
step s24 240 python3 -m bench.runner --device cuda --section 24 --worlds 16384 --worlds 65536 --out /tmp/r24
keep r24
# The faster solver on CUDA by section 24 (median at rest and with presses, both sizes, every
# fidelity check passed) is what section 25's service and engine step with.
W=$(python3 -c "
import json, math
d = json.load(open('/tmp/r24/warp_solvers_cuda.json'))
r = [d['results'][n][load][s]['median'] / d['results'][n][load]['cg']['median']
     for n in d['results'] for load in ('rest', 'presses') for s in ['newton']]
ok = d['fidelity'].get('newton', {}).get('passes')
print('NEWTON' if ok and r and math.prod(r) ** (1 / len(r)) > 1 else 'CG')" 2>>$L)
echo "section 25 steps with: ${W:-CG}" | tee -a $L
[ "$W" = NEWTON ] && sed -i 's/"warp_cuda": mujoco.mjtSolver.mjSOL_CG/"warp_cuda": mujoco.mjtSolver.mjSOL_NEWTON/' service/core/sim/physics.py
grep -n '"warp_cuda"' service/core/sim/physics.py | tee -a $L
step s25 220 python3 -m bench.runner --device cuda --section 25 --worlds 16384 --out /tmp/r25
keep r25
P="import json; from bench.tick_profile import profile; r=profile(16384,'cuda:0','binary',4.0,'packed'); print('served', json.dumps({k: r[k] for k in ('engine_ms_per_tick','served_ms_per_tick','served_vs_engine','seconds_per_s','ms_per_call')}))"
step prof 60 python3 -c "$P"
;;
c)
rm -rf ~/.cache/warp && mkdir -p ~/.cache && $Z -d -q -c $B/warpcache.tar.zst | tar -xf - -C ~/.cache || exit 1
rm -rf /tmp/fix && cp -a $NEW /tmp/fix
sed -i 's/^SWITCH_INTERVAL_S = 0.0005$/SWITCH_INTERVAL_S = 0.0001/' /tmp/fix/service/core/sim/pace.py
grep -n "^SWITCH_INTERVAL_S" /tmp/fix/service/core/sim/pace.py service/core/sim/pace.py | tee -a $L
cd /tmp/fix; export PYTHONPATH=/tmp/fix:$S
step fix16 200 python3 -m bench.runner --device cuda --section 25 --worlds 16384 --out /tmp/r_fix16
keep r_fix16
cd $NEW; export PYTHONPATH=$NEW:$S
step base16 200 python3 -m bench.runner --device cuda --section 25 --worlds 16384 --out /tmp/r_base16
keep r_base16
step base65 240 python3 -m bench.runner --device cuda --section 25 --worlds 65536 --out /tmp/r_base65
keep r_base65
;;
esac
echo "done at $SECONDS s" | tee -a $L
