"""Driving an arm: what the control loop reads from an arm and sends to it
(:mod:`~qpavoid.drive.interface`), the kinematic simulation of one, and adapters for real
arms (:mod:`~qpavoid.drive.franka`, through ``franky-control``).

May import: every stage above it (core to control).
"""
