"""Engines: the implementations of the core's `Batch` protocol, and the choice among them.

Lives here: Warp on one device (`warp`), native MuJoCo on a thread pool (`native`), process
shards (`shards`, their worker `shard_worker`), Ray actors (`ray_shards`, `ray_actor`; a
`--ray local` instance's processes: `ray_local`), what the
sharded engines share (`sharding`), the host-side mirror of targets, ticks and faults every
engine keeps (`mirror`), the usable-cores helper (`cores`), the engine the settings ask
for (`choice`, which also checks the CUDA devices they name) and those settings
(`settings`). tests/test_batch_contract.py runs the same checks on every engine.

May import: `service.core`; never persistence, surfaces, api or the app.
"""
