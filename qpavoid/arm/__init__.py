"""The arm: its description (URDF, roles, capsules, dynamics), its Pinocchio model and
kinematics, its inverse kinematics and reach, and how it brakes.

May import: core.
"""
