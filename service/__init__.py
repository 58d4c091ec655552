"""swarmpose: markerless 3D human pose tracking for RGBD cameras.

A personalised skinned body model is fitted to each depth frame by particle swarm
optimisation of an objective that combines the rendered-vs-observed depth discrepancy
with the distance to 2D joints found by a neural detector.
"""

__version__ = "0.1.0"
