"""Persistence: what outlives the process.

Lives here: snapshot files (`snapshots`) and the batch header they must match (`provenance`),
MCAP recordings (`recorder`, `mcap_log`), `armfleet replay` (`replay`), and opening files for
writing so that failures name their cause and a stuck reader cannot hang a writer (`storage`).

May import: `service.core` and `service.engines`; never surfaces, api or the app.
"""
