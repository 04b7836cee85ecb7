"""The simulation: the engine protocol (`batch`), domain types, the robot and physics read from
the MJCF, the scene and its entity table (`entities`), the loop that owns the batch on a thread
of its own (`loop`; what it hands out and takes in, `loop_types`; its command side,
`command_desk` over `staging`'s table; who hears from it, `listeners`; what other threads wait
on, `waiters`; how it keeps and reports time, `pace`; its state taken, restored and written
while paused, `loop_state`), and the rules the loop applies to what it is given (`rules`: world
ids and the JointState rule; `arithmetic`: clamped target updates), and what the simulation is
asked to be (`settings`: worlds, scene, mode, rates).

May import: `service.core.errors`, `service.core.process`; nothing else of the core.
"""
