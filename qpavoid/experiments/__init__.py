"""Runs and their sets: one run from its spec, comparisons, safety campaigns and sweeps,
the benchmark.

May import: every stage above it (core to output).
"""
