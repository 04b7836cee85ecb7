"""HTTP and WebSocket routes, one router per resource: part of the app.

Routes reach the running service through `deps` (the runtime, its loop and `Control`) and map
nothing themselves: domain errors become statuses once, in app.py. May import anything below
(core, engines, persistence, surfaces) and the runtime.
"""
