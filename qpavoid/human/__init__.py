"""The person as data: skeleton formats, one frame of a skeleton or of several people,
the upper-body model of capsules, and postures.

May import: core.
"""
