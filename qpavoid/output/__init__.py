"""What a run leaves: its files, its figures, its browser replay and the live view.

May import: every stage above it (core to scenarios).
"""
