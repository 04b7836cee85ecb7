"""Foxglove: everything of the service that speaks Foxglove's formats, through its SDK.

Lives here: the live WebSocket server (`live`: joint states, transforms and the scene of the
shown worlds, commands back), what it draws of a world (`scene`), who each of its clients is
(`callers`), camera images as Foxglove topics (`camera_topics`), the camera recording, an MCAP
file of those topics (`camera_recording`), and the settings of both surfaces (`settings`).
Only this folder imports the Foxglove SDK, and only when a surface of it is asked for.
"""
