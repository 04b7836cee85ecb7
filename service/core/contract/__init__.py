"""The HTTP contract: reply models (`replies`, with the OpenAPI fit), snapshots' and the
drawable scene's shapes. Request bodies live with their commands.

May import: every other room of the core (it describes what they answer).
"""
