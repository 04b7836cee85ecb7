"""Cameras: which the scene has and at what size (`catalog`), pictures taken on request
(`feed`), their wire forms (`wire`), and one picture clock per camera and rate (`clock`).

May import: `commands`, `streams`, `sim` and below.
"""
