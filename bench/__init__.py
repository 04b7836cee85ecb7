"""`armfleet bench`: the engine and the service measured against native MuJoCo and raw MuJoCo Warp.

Sections (each a module runnable on its own with ``python -m bench.<module>``):

1. ``bench.throughput``: world-steps/s of the engine's captured tick, raw MuJoCo Warp (captured and
   plain ``mjw.step``) and ``mujoco.rollout`` (1 thread, all cores), same model and step.
2. ``bench.service_bench``: the service in ``fast`` mode streaming every world at 30 Hz.
3. ``bench.service_bench`` (``--capacity``): the largest batch that ``realtime`` mode keeps at RTF
   >= 0.99.
4. ``bench.latency``: WebSocket increment → target in a frame → joint moving.
5. ``bench.http_bench``: HTTP increments/s, 1 and 8 keep-alive clients.
6. ``bench.startup``: process start → ``/readyz`` with a cold and a warm kernel cache.

``bench.suite.run_suite`` runs them in order and writes ``bench/results/``.
"""
