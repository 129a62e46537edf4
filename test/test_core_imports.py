"""The numerical core imports and runs with rclpy and rerun unavailable."""

import os
import subprocess
import sys

BLOCKED = ('rclpy', 'rerun', 'sensor_msgs', 'geometry_msgs', 'std_srvs', 'std_msgs')
CORE = ('conventions', 'schema.scene', 'core.linalg', 'core.planar.kinematics',
        'core.planar.dynamics', 'core.equimomental', 'analysis.cycle', 'core.spatial.rig',
        'balancing.redistribution', 'balancing.spatial', 'balancing.weights', 'analysis.identify',
        'ros.bags', 'ros.urdf')

SCRIPT = f"""
import importlib.abc, sys
BLOCKED = {BLOCKED!r}
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ImportError('blocked for this test: ' + name)
        return None
sys.meta_path.insert(0, Block())
import importlib
for mod in {CORE!r}:
    importlib.import_module('mech_balance.' + mod)
from mech_balance.analysis import cycle as analysis
from mech_balance import schema as scene
cycle = analysis.run_cycle(analysis.Rig(scene.load('hoeken')), 36)
assert cycle.wrenches.shaking_moment.shape == (36,)
loaded = sorted(m for m in sys.modules if m.split('.')[0] in BLOCKED)
print('loaded:', loaded)
"""


def test_core_runs_without_ros_and_rerun():
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root)
    proc = subprocess.run([sys.executable, '-c', SCRIPT], env=env, capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert 'loaded: []' in proc.stdout
