"""Layer 0, the shared base: rotations, JSON conventions, geodesy and the CLI's error type.

Modules here import nothing of the project but each other (and :mod:`vtolftc.airframe`, the
other layer-0 package).
"""
