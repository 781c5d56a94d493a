"""One tick's state and the controllers that read it: the paper's (analytic) and the QP
controller (``control.qp``, with its tasks, limits and barriers), and the planned task.

May import: every stage above it (core to laws).
"""
