"""Persistence: what outlives the process.

Lives here: snapshot files (`snapshots`) and the batch header they must match (`provenance`),
MCAP recordings (`recorder`, `mcap_log`) and `armfleet replay` (`replay`).

May import: `service.core` and `service.engines`; never surfaces, api or the app.
"""
