"""Tracked people as the controller sees them: filtered joints and inflated capsules.

May import: core, human, sensing, fusion.
"""
