"""The people a run is about: motions made in code, strikes, recordings to run.

May import: every stage above it (core to loop).
"""
