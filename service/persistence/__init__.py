"""Persistence: what outlives the process.

Lives here: the one persistence service of a running armfleet (`service`: snapshots and the
recording together), snapshot files (`snapshots`) and the batch header a state must match
(`provenance`), MCAP recordings (`recorder` writes one off the sim thread, `mcap_log` is the
layout) and `armfleet replay` (`replay`, which gives its recorder the same `SurfaceContext` a
service would), and files opened for writing so that failures name their cause and a stuck
reader cannot hang a writer (`storage`), and what persistence is asked to keep (`settings`).

May import: `service.core` and `service.engines`; never surfaces, api or the app.
"""
