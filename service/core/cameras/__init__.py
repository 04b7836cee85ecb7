"""Cameras: which the scene has and at what size (`catalog`), pictures taken on request
(`feed`), their wire forms (`wire`), one picture clock per camera and rate (`clock`), and
what the cameras are asked to draw (`settings`).

May import: `commands`, `streams`, `sim` and below.
"""
