"""Closing the loop: the simulation and the real-time loop, the simulated camera, the live
input, the truth every clearance is measured against, the log and the metrics.

May import: every stage above it (core to control).
"""
