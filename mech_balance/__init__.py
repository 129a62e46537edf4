"""
Digital twin of a balanced mechanism test rig.

The numerical core (``mech_balance.core`` and friends) imports numpy and scipy only; the
ROS 2 node and the rerun recorder live in their own modules and are imported on demand.
"""

__version__ = '0.1.0'
