"""The service's process: who stops on SIGINT/SIGTERM (`stopping`), and a sourced ROS 2
shell's PYTHONPATH kept out of our interpreter (`pythonpath`).

May import: `service.core.errors` only (it sits under every other room).
"""
