"""Who may read and who may command: the access policy and its middlewares (`policy`), who
sends a command (`callers`), leases (`leases`, their bodies and metrics), and the log filter
that blanks tokens (`redact`).

May import: `cameras`, `commands`, `streams`, `sim` and below.
"""
