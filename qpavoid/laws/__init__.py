"""The paper's laws, eqs. (2)-(9), and ISO/TS 15066 speed and separation.

May import: core, arm, human, distance.
"""
