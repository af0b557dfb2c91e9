"""Physiological experiments on finite-element bodies.

* :mod:`~harpx.physiology.active`: active contraction, forward simulations of activation
  (:func:`~harpx.physiology.active.simulate_activation`).
* :mod:`~harpx.physiology.growth`: prestretch by growth (residual stress of a stress-free
  body grown into its imaged shape).
* :mod:`~harpx.physiology.cut`: cutting a body open to release residual stress.

Units: mm, kPa.
"""
