"""Commands: one class per kind, and the one list of them (`registry.COMMANDS`).

A command class (`base.Command`) owns everything about its kind: its wire form (`from_wire`,
the body of its WebSocket op, validated by the same pydantic model as its HTTP body; `ack`, the
reply), its validation (in its constructors, once, each error naming the field and the limit;
the shared rules are in `rules`: world ids, JointState-shaped names and positions; clamping is
in `arithmetic`), how it is staged at a tick boundary (`stage`, through the loop's command
tables and the trajectory runner: `base.Door`), what listeners hear of it (`announce`: worlds,
targets, tick and its record fields, written to MCAP by the recorder), how replay re-applies a
recorded one (`from_record`), its metrics label (`kind`) and the worlds it writes (`touches`,
which the lease gate checks before it is staged; None: every world, the administrator's).

`Control.run(command, source)` is the one way to run any of them, from every surface.

To add a command:

1. write its class in a module of this package (or of the feature it belongs to): `kind`,
   `op` if the WebSocket takes it, `http` for the last segment of its HTTP write path, a
   `create` class method that validates, `stage`, `touches`, and `announce` / `ack` /
   `from_record` as it needs;
2. add it to `registry.COMMANDS`;
3. only if it writes a kind of engine state no command wrote before: add that to
   `service.core.sim.batch.TickWrites` (what every engine applies at a tick boundary).

An HTTP route, if it has one, is a few lines in `service/api` calling `Control.run`.
"""

from service.core.commands.base import BROWSER, HTTP, REPLAY, WS, Accepted, Command, Door

__all__ = ["BROWSER", "HTTP", "REPLAY", "WS", "Accepted", "Command", "Door"]
