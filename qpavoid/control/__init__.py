"""One tick's state and the controllers that read it: the paper's (analytic) and the QP
controller (``control.qp``, with its tasks, limits and barriers), the planned path and the
task file that gives each arm its own.

May import: every stage above it (core to laws).
"""
