"""The robot's own interfaces: every world answers as a UR10e controller does, on an address
of its own (`armfleet serve --ur`).

Lives here: where each world listens (`addresses`: the loopback mapping or the user's IP
aliases), the per-world controller state that the Dashboard sets and RTDE reports
(`controller`), one world's controller as its connections see it (`world_robot`), RTDE
(`rtde_wire`: framing and the protocol's packages; `rtde_variables`: the recipe variables and
their types; `rtde_frame`: every world's values at a tick, once per tick in one batch;
`rtde_outputs`: a recipe's values of one world at the tick; `tcp_pose`: MuJoCo's flange/TCP
pose and speed for an arm that is not UR's DH chain; `rtde_pacer`: one timer per frequency
for every stream; `rtde_session`: one connection), the
Dashboard server (`dashboard`), the script ports 30001-30003 (`script_ports`), the listeners
on a thread and event loop of their own (`endpoints`), the surface, its sink and `GET /v1/ur`
(`surface`), and its settings (`settings`). Imports as its parent package (surfaces): the
core, never the app or another surface.
"""
