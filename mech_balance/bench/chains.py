"""Generated single-input planar chains (docs/benchmarks.md#the-generated-chains)."""

import math

from mech_balance import schema as scene_mod

STAGE0 = {'crank': 1.0, 'coupler': 4.0, 'rocker': 3.0, 'frame': 4.0}
"""Stage-0 four-bar in crank lengths: Grashof crank-rocker, transmission angle 48-90 deg."""
STAGE_SPACING = 4.0
"""Frame spacing between successive rocker pivots, in crank lengths."""
DEFAULT_SKEW = 0.03
"""Relative length change of each later stage's coupler and rocker off the parallelogram."""
COM_OFFSET = 0.1
"""Mass-centre offset from the joint line, as a fraction of the link length."""
MAX_LOOPS = 200
"""Largest number of loops :func:`dyad_chain` builds."""


def link_counts(loops):
    """Return ``(moving links, links counting the frame, joints)`` of a chain of ``loops``."""
    return 2 * loops + 1, 2 * loops + 2, 3 * loops + 1


def _bar(length_m, density_kg_m):
    """Return the mass properties of a uniform bar along x, its centre moved off the line."""
    mass = density_kg_m * length_m
    return {'mass_kg': mass, 'com_m': [0.5 * length_m, COM_OFFSET * length_m],
            'inertia_com_kg_m2': mass * length_m ** 2 / 12.0}


def dyad_chain(loops, crank_m=0.05, density_kg_m=2.0, speed_rad_s=1.0, skew=DEFAULT_SKEW):
    """
    Return a planar :class:`~mech_balance.schema.scene.Scene` with ``loops`` closed loops.

    ``2 loops + 1`` moving links, ``3 loops + 1`` revolute joints, input joint ``O1``.
    """
    if isinstance(loops, bool) or not isinstance(loops, int) or not 1 <= loops <= MAX_LOOPS:
        raise ValueError(f'loops: got {loops!r}, expected an integer from 1 to {MAX_LOOPS}')
    for name, value in (('crank_m', crank_m), ('density_kg_m', density_kg_m),
                        ('speed_rad_s', speed_rad_s)):
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise ValueError(f'{name}: got {value!r}, expected a positive finite number')
    if not (isinstance(skew, (int, float)) and 0.0 <= skew < 0.2):
        raise ValueError(f'skew: got {skew!r}, expected a number in [0, 0.2)')
    u = float(crank_m)
    a, b, c, d = (STAGE0[k] * u for k in ('crank', 'coupler', 'rocker', 'frame'))
    theta2, theta3 = _dyad_angles(complex(a, 0.0), complex(d, 0.0), b, c)
    frame = {'O1': [0.0, 0.0], 'P0': [d, 0.0]}
    links = {
        'crank': {'points': {'O1': [0.0, 0.0], 'A': [a, 0.0]}, **_bar(a, density_kg_m)},
        'coupler0': {'points': {'A': [0.0, 0.0], 'B': [b, 0.0]}, **_bar(b, density_kg_m)},
        'rocker0': {'points': {'P': [0.0, 0.0], 'B': [c, 0.0]}, **_bar(c, density_kg_m)},
    }
    joints = {
        'O1': {'type': 'revolute', 'a': 'frame.O1', 'b': 'crank.O1'},
        'A': {'type': 'revolute', 'a': 'crank.A', 'b': 'coupler0.A'},
        'B0': {'type': 'revolute', 'a': 'coupler0.B', 'b': 'rocker0.B'},
        'P0': {'type': 'revolute', 'a': 'frame.P0', 'b': 'rocker0.P'},
    }
    angles = {'coupler0': math.degrees(theta2), 'rocker0': math.degrees(theta3)}
    pivot_x, rocker_len, rocker_angle = d, c, theta3
    for k in range(1, loops):
        e = skew if k % 2 else -skew
        b_k = STAGE_SPACING * u * (1.0 + e)
        c_k = STAGE0['rocker'] * u * (1.0 - e)
        s = STAGE_SPACING * u
        prev = f'rocker{k - 1}'
        pivot_x += s
        frame[f'P{k}'] = [pivot_x, 0.0]
        links[f'coupler{k}'] = {'points': {'B': [0.0, 0.0], 'D': [b_k, 0.0]},
                                **_bar(b_k, density_kg_m)}
        links[f'rocker{k}'] = {'points': {'P': [0.0, 0.0], 'B': [c_k, 0.0]},
                               **_bar(c_k, density_kg_m)}
        joints[f'C{k}'] = {'type': 'revolute', 'a': f'{prev}.B', 'b': f'coupler{k}.B'}
        joints[f'D{k}'] = {'type': 'revolute', 'a': f'coupler{k}.D', 'b': f'rocker{k}.B'}
        joints[f'P{k}'] = {'type': 'revolute', 'a': f'frame.P{k}', 'b': f'rocker{k}.P'}
        # the previous rocker's tip drives a four-bar with frame spacing s: its own angles
        tip = rocker_len * complex(math.cos(rocker_angle), math.sin(rocker_angle))
        start = complex(pivot_x - s, 0.0) + tip
        theta_c, theta_r = _dyad_angles(start, complex(pivot_x, 0.0), b_k, c_k)
        angles[f'coupler{k}'] = math.degrees(theta_c)
        angles[f'rocker{k}'] = math.degrees(theta_r)
        rocker_len, rocker_angle = c_k, theta_r
    n_moving, n_all, n_joints = link_counts(loops)
    data = {
        'name': f'dyad_chain_{loops}',
        'description': (f'Generated chain: a crank-rocker four-bar and {loops - 1} '
                        f'near-parallelogram stages; {n_moving} moving links ({n_all} with the '
                        f'frame), {n_joints} revolute joints, {loops} loops.'),
        'kind': 'planar',
        'crank': {'joint': 'O1', 'speed_rad_s': float(speed_rad_s), 'acceleration_rad_s2': 0.0},
        'frame': {'points': frame},
        'links': links,
        'joints': joints,
        'assembly': {'crank_angle_deg': 0.0, 'link_angles_deg': angles},
        'outputs': list(scene_mod.OUTPUTS),
        'samples': 360,
    }
    return scene_mod.from_dict(data, source=f'<mech_balance.bench.chains.dyad_chain({loops})>')


def _dyad_angles(start, pivot, coupler, rocker):
    """Return (coupler, rocker) angles closing start -> joint <- pivot, joint above the line."""
    diff = pivot - start
    r = abs(diff)
    along = (coupler * coupler - rocker * rocker + r * r) / (2.0 * r)
    h = math.sqrt(max(coupler * coupler - along * along, 0.0))
    unit = diff / r
    joint = start + unit * complex(along, h)
    return math.atan2((joint - start).imag, (joint - start).real), \
        math.atan2((joint - pivot).imag, (joint - pivot).real)
