"""Suspension tuning of a Land Rover Defender 110 with 4S4 struts.

Implements Thoresson, Uys, Els and Snyman (2009), "Efficient optimisation of a
vehicle suspension system, using a gradient-based approximation method. Part 1".

Layers
------
``suspension_tuning.vehicle``
    Physics: full nonlinear vehicle model, simplified models, road, manoeuvre,
    comfort weighting, objectives and constraints.  Never imports rclpy.
``suspension_tuning.optim``
    Dynamic-Q with LFOPC, finite differences, eq. 25 scaling.  Never imports rclpy.
``suspension_tuning.nodes``
    Thin rclpy adapters over the two layers above.
"""

__version__ = '0.1.0'
