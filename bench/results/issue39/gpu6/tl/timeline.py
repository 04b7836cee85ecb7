"""Run the timeline probe: `armfleet serve --mode fast` at N worlds on CUDA with one binary 30 Hz
subscriber to every world (section 25's service run), then the engine loop alone.

Run from a source tree's root: python3 PATH/timeline.py OUTDIR [worlds]
"""

import asyncio
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.getcwd())

from bench import common  # noqa: E402
from bench.service_probe import measure_fast  # noqa: E402


def main() -> None:
    out, n = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 16384
    os.makedirs(out, exist_ok=True)
    svc = os.path.join(out, f"service_{n}.json")
    env = {
        "PYTHONPATH": HERE + ":" + os.environ.get("PYTHONPATH", ""),
        "TL_OUT": svc,
    }
    device = os.environ.get("TL_DEVICE", "cuda")
    with common.served(n, "fast", device, env) as server:
        res = asyncio.run(measure_fast(server, 12.0, 2.0, "binary"))
        print("service", {k: res[k] for k in ("ticks_per_s", "world_steps_per_s", "frames_per_s")})
        t0 = time.time()
        while not os.path.exists(svc) and time.time() - t0 < 30:
            time.sleep(0.5)
    if device != "cuda":
        return
    import tlpatch

    tlpatch.engine_only(n, 1500, os.path.join(out, f"engine_{n}.json"))
    print("done")


if __name__ == "__main__":
    main()
