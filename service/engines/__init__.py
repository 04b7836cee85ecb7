"""Engines: implementations of the core's `Batch` protocol.

Lives here: Warp (`warp`), native MuJoCo (`native`), process shards (`shards`), Ray actors
(`ray_shards`; a `--ray local` instance's processes: `ray_local`) and the sharding plan they
share (`sharding`).

May import: `service.core`; never persistence, surfaces, api or the app.
"""
