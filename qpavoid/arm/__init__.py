"""The arm: its description (URDF, roles, capsules, dynamics), its Pinocchio model and
kinematics, and how it brakes.

May import: core.
"""
