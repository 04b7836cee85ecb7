"""The core: what every engine, surface and route shares, and the one path of a command.

Lives here: the domain types (`types`) and the engine protocol with its optional capabilities
(`batch`), the robot read from the MJCF (`robot`, `physics`), domain errors, command arithmetic
(`commands`), the simulation loop (`loop`, `loop_boundary`, `loop_types`, `staging`, and the
trajectories it samples, `trajectory/`), `Control` (the one door for commands from every
surface), the state hub, wire shapes (`wire`), the world-list parser (`worlds`), the API
schemas (`schemas`, `schema_fields`), settings, access policy, metrics, the drawable scene, the
surface plug-in point (`surface`), and who stops on SIGINT/SIGTERM (`stopping`).

May import: the standard library, third-party packages, `mjcf` and `clients.models` (the wire's
own description of a joint); never engines, persistence, surfaces, api or the app.
"""
