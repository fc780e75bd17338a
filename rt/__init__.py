"""talus real-time side: robot model, twin, hardware backends, loop, supervisor.

Everything in this package is Qt-free (Qt lives only in ``app/``).
"""
