"""Robot-human distance tables: spheres and exact capsules, one result type.

May import: core, arm, human, perception.
"""
