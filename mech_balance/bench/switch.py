"""The ``scene switch`` rows of the node's bench: a switch until the new rig publishes."""

import os
import time

SWITCH_RATE_HZ = 250.0
"""Clock-mode publish rate during the switches (a message every 4 ms)."""
TARGET_SWITCH_S = 0.5
"""Issue 31 item 3: set call to the new rig's first joint_states, every built-in."""
SETTLE_S = 0.3
"""Publishing of the previous scene before the next switch."""
SWITCH_TIMEOUT_S = 30.0
"""Longest wait for one switch."""


def published_names(scene_name):
    """Return the joint names the node publishes for built-in ``scene_name``."""
    from mech_balance.ros import parameters
    return tuple(parameters.build_model(scene_name).joint_names)


def switch_times(names, domain=None, progress=print):
    """
    Return ``{scene: [(answer_s, first_sample_s), (the same again)]}``: switches to ``names``.

    Set call to answer and to the first joint_states; first switch, then a later one.
    """
    from mech_balance.bench.node import NodeProbe
    from rclpy.parameter import Parameter
    from sensor_msgs.msg import JointState
    from rclpy.qos import QoSProfile

    expected = {name: published_names(name) for name in names}
    start = 'hoeken' if 'hoeken' in names else names[0]
    probe = NodeProbe(start, SWITCH_RATE_HZ, f'/switch{os.getpid()}', domain=domain,
                      label='switch')
    seen = []   # (monotonic s, names) of every joint_states received

    def keep(msg):
        seen.append((time.monotonic(), tuple(msg.name)))
    probe.node.create_subscription(JointState, f'{probe.ns}/joint_states', keep,
                                   QoSProfile(depth=1000))
    out = {}

    def switch(name):
        seen.clear()
        t0 = time.monotonic()
        future = client.set_parameters([Parameter('scene', value=name)])
        probe.spin_for(SWITCH_TIMEOUT_S, lambda: future.done() and any(
            n == expected[name] for _, n in seen))
        if not (future.done() and future.result().results[0].successful):
            raise RuntimeError(f'could not set scene to {name!r}')
        answered = time.monotonic()
        first = next((t for t, n in seen if n == expected[name]), None)
        if first is None:
            raise RuntimeError(f'scene {name!r}: no joint_states with its joints within '
                               f'{SWITCH_TIMEOUT_S:g} s')
        probe.spin_for(SETTLE_S)
        return answered - t0, first - t0

    try:
        client = probe.parameter_client()
        current = start
        for name in names:   # the first switch to each: what a user's first switch costs
            if expected[name] == expected[current]:
                other = next(n for n in names if expected[n] != expected[name])
                switch(other)
            progress(f'    scene switch -> {name} ...')
            out[name] = [switch(name)]
            current = name
        for name in names:   # again, warm
            other = next(n for n in names if expected[n] != expected[name])
            switch(other)
            out[name].append(switch(name))
    finally:
        probe.close()
    return out


def switch_lines(names, progress=print):
    """Return the bench lines of the ``scene switch`` rows (one per scene, then a verdict)."""
    try:
        times = switch_times(list(names), progress=progress)
    except (RuntimeError, OSError) as exc:
        return [f'scene switch: not measured ({exc})']
    head = (f"{'scene switch to':<20}{'answer s':>10}{'first sample s':>16}"
            f"{'again: answer':>15}{'first sample':>14}  result")
    lines = ['', f'scene switch (ros2 param set scene, node in its own process at '
             f'{SWITCH_RATE_HZ:g} Hz): from the set call to its answer and to the first '
             "joint_states with the new scene's joints", head, '-' * len(head)]
    for name, ((answer, first), (answer2, first2)) in times.items():
        lines.append(f'{name:<20}{answer:>10.3f}{first:>16.3f}{answer2:>15.3f}{first2:>14.3f}'
                     f'  {"met" if max(first, first2) <= TARGET_SWITCH_S else "NOT met"}')
    worst = max(max(first for _, first in pairs) for pairs in times.values())
    lines.append(f'target: the new rig published within {TARGET_SWITCH_S:g} s of the set '
                 f'call for every built-in {"met" if worst <= TARGET_SWITCH_S else "NOT met"}'
                 f' (worst {worst:.3f} s)')
    return lines


def switch_section(args, progress):
    """Return the ``scene switch`` table of every built-in (a ``mech-balance bench`` section)."""
    from mech_balance.schema.scene import builtin_scenes
    return '\n'.join(switch_lines(sorted(builtin_scenes()), progress))


if __name__ == '__main__':
    import sys
    from mech_balance.schema.scene import builtin_scenes
    for line in switch_lines(sys.argv[1:] or sorted(builtin_scenes())):
        print(line)
