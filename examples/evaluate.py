"""
Evaluate a rig at a few crank angles: motion, driving torque, bearing reactions, shaking wrench.

::

    python examples/evaluate.py [SCENE]      # default: hoeken

Every figure is SI, in the frame's axes; the shaking wrench is what the moving links exert
on the frame, about the rig's moment point (README "Conventions").
"""

import sys

import mech_balance as mb
import numpy as np

scene = mb.load_scene(sys.argv[1] if len(sys.argv) > 1 else 'hoeken')
rig = mb.rig_for(scene)
angles_deg = np.array([0.0, 90.0, 180.0, 270.0])
data = rig.at(np.radians(angles_deg), speed=scene.crank_speed_rad_s, accel=0.0,
              outputs=('kinematics', 'shaking_wrench', 'driving_torque', 'bearing_reactions'))
effort = 'driving_force' if 'driving_force' in data.series else 'driving_torque'

print(f'{scene.name}: crank speed {scene.crank_speed_rad_s:g} rad/s, joints '
      f'{", ".join(data.joint_names)}')
for k, deg in enumerate(angles_deg):
    print(f'crank {deg:g} deg')
    print('  joint positions:', ' '.join(f'{q:.6g}' for q in data.joint_position[k]))
    print(f'  {effort}: {data.series[effort][k]:.6g}')
    for joint, (force, _) in data.reactions.items():
        print(f'  bearing {joint} force:', ' '.join(f'{f:.6g}' for f in force[k]))
    print('  shaking force N:', ' '.join(f'{f:.6g}' for f in data.force_N[k]))
    print('  shaking moment N m:', ' '.join(f'{n:.6g}' for n in data.moment_Nm[k]))
    print(f'  loop closure residual {data.residual[k]:.1e}, condition {data.condition[k]:.3g}')
