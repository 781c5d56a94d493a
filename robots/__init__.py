"""Robot descriptions shipped with qpavoid (installed as ``qpavoid.robots``).

Each folder holds a URDF and a ``control_points.toml``; see docs/robot.md.
"""
