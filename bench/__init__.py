"""`armfleet bench`: the engine and the service measured against native MuJoCo and raw MuJoCo Warp.

bench.registry says what a section is and how to add one; bench.runner runs them (``armfleet bench
--list`` names them). One module a subject: throughput (1), service_bench (2, 3, 7), latency (4),
http_bench (5), startup (6), ...; common holds what they share, baselines the raw MuJoCo Warp and
native rollout they compare with, service_probe the windows measured from a served batch's
client, plot draws throughput.png.
"""
