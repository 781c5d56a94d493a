"""Driving an arm: what the control loop reads from an arm and sends to it
(:mod:`~qpavoid.drive.interface`), the kinematic simulation of one, and adapters for real
arms: a Franka arm through the binding of libfranka its controller speaks
(:mod:`~qpavoid.drive.libfranka`, what they share; which arm answers,
:mod:`~qpavoid.drive.franka_model`; its joints, :mod:`~qpavoid.drive.franka_joints`; the
connection and its failures, :mod:`~qpavoid.drive.libfranka_connection`; its state and
rest, :mod:`~qpavoid.drive.libfranka_state`): the FR3 through ``franky-control``
(:mod:`~qpavoid.drive.franka`), the Panda through ``panda-python``
(:mod:`~qpavoid.drive.panda`).

May import: every stage above it (core to control).
"""
