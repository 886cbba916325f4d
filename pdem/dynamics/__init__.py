"""pdem.dynamics: rigid-block motion (eqs. 44-52), damping (77-83), timestep (84-89).

Modules: ``rotation`` (quaternion kernels), ``motion`` (``integrate``, damping modes,
start-up helpers, adaptive-damping servo), ``timestep`` (critical step, mass scaling),
``energy`` (kinetic energy and momenta for reporting).
"""
