"""The service's process: who stops on SIGINT/SIGTERM (`stopping`), a sourced ROS 2 shell's
PYTHONPATH kept out of our interpreter (`pythonpath`), how a settings section declares the
flat names the process is configured by (`flat_names`: ARMFLEET_* variables, serve options), and
the request-handling thread's lower priority beside the ticks (`priority`), and the engine's
raised one where the process may raise it (`engine_priority`), and spawned workers that skip
importing the main module again (`lean_spawn`).

May import: `service.core.errors` only (it sits under every other room).
"""
