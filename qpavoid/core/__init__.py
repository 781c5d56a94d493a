"""What every stage shares: the library's errors, argument checks, small vector helpers,
the numba compiling helpers and the handling of Ctrl-C and SIGTERM.

Imports no other qpavoid stage.
"""
