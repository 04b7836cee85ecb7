"""The core: what every engine and surface shares.

Lives here: the domain types and the `Batch` protocol (types), the robot read from the MJCF,
physics options, domain errors, command arithmetic, the simulation loop, `Control` (the one door
for commands), the state hub, wire shapes, the API schemas, settings, access policy, metrics,
and who stops on SIGINT/SIGTERM (stopping).

May import: the standard library, third-party packages and `mjcf`; never engines, persistence,
surfaces, api or the app.
"""
