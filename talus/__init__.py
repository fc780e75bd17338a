"""The ``talus`` entry point: the command line and the composition of the parts.

``rt`` (the real-time side) imports nothing above it; which programs and sessions the RT process
offers, and which command groups exist, is decided here, where every package is known.
"""
