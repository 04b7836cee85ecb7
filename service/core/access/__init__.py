"""Who may read and who may command: the access policy and its middlewares (`policy`), who
sends a command (`callers`), leases (`leases`, their bodies and metrics), the log filter
that blanks tokens (`redact`), and what access is asked to be (`settings`).

May import: `cameras`, `commands`, `streams`, `sim` and below.
"""
