"""Several sensors' bodies merged into people: association, admission, the tracks.

May import: core, human, sensing.
"""
