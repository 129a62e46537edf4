"""
What the rig node publishes, shared by its parts: the parameter values and the designs.

No ROS here.  One :class:`RigState` per node; every part reads and changes it under
:attr:`RigState.lock` (re-entrant: a part may call another part while holding it).
"""

import threading


class RigState:
    """
    The checked parameter values and the designs of a rig node (one lock for all).

    ``original`` (the scene's twin, calibrated after ``~/identify``), ``balanced`` (or
    None), ``published``; ``calibration``: ``(calibrated, replaced model, bias before)``.
    """

    def __init__(self, values, original):
        self.lock = threading.RLock()
        self.values = values
        self.original = original
        self.balanced = None
        self.published = original
        self.calibration = None

    def crank_speed(self):
        """Return the clock-mode crank speed, rad/s (``crank_speed``, 0: the scene's)."""
        speed = self.values['crank_speed']
        return speed if speed != 0.0 else self.original.scene.crank_speed_rad_s

    def wanted_design(self):
        """Return the design ``use_balanced`` asks for, or None (a balancing run is due)."""
        with self.lock:
            if not self.values['use_balanced']:
                return self.original
            return self.balanced
