"""
Follow mode answers every encoder sample or counts it (issue 32 item 3).

An encoder stream with samples left out (gaps in its stamps) and bad messages in between:
the node's stats line accounts for every one -- published, or counted as not answered with
its reason (missing from the gaps, rejected, priming the estimator).  Real rclpy across
processes; counts, never a rate or a time.
"""

import json
import math
import os
import sys

from mech_balance import schema as scene_mod
from mech_balance.ros import node as rig_node

sys.path.insert(0, os.path.dirname(__file__))
import test_node as tn  # noqa: E402, I100

SAMPLES = 600
LEFT_OUT = (100, 101, 102, 300, 450)
"""Indices of the 1 kHz stream never sent (the middleware lost them, say)."""
BAD_AFTER = (200, 400)
"""A message without the crank joint follows these indices."""


def test_every_encoder_sample_is_answered_or_counted(context):
    ns = tn._namespace('follow_counts')
    rig = tn.RigProcess(ns, '-p', 'scene:=slider_crank', '-p', 'mode:=follow')
    probe = tn.Probe(context, ns)
    omega = scene_mod.load('slider_crank').crank_speed_rad_s
    t0, dt = 1_000 * 10 ** 9, 1_000_000
    try:
        probe.wait_for_rig(rig)
        probe.spin_until(lambda: probe.encoder.get_subscription_count() >= 1,
                         tn.DISCOVERY_TIMEOUT_S, 'the node to subscribe to the encoder')
        probe.after_ns = -1
        sent = 0
        for k in range(SAMPLES):
            t = t0 + k * dt
            if k not in LEFT_OUT:
                angle = (0.3 + omega * k * dt * 1e-9 + math.pi) % (2 * math.pi) - math.pi
                probe.encoder.publish(tn._encoder(['O'], t, [angle]))
                sent += 1
            if k in BAD_AFTER:
                probe.encoder.publish(tn._encoder(['X'], t + 1, [0.0]))
                sent += 1
            probe.executor.spin_once(timeout_sec=0.0)
        last = t0 + (SAMPLES - 1) * dt
        probe.spin_until(lambda: any(j[0] == last for j in probe.joints),
                         what='the sample of the last encoder message')
    finally:
        probe.destroy()
        log = rig.stop()
    line = [x for x in log.splitlines() if rig_node.STATS_TAG in x][-1]
    stats = json.loads(line.split(rig_node.STATS_TAG, 1)[1])
    follow, unanswered = stats['follow'], stats['follow']['unanswered']
    print(line.split(rig_node.STATS_TAG)[0][-400:])
    assert follow['received'] == sent
    missing = unanswered.pop('missing (gaps in the encoder stamps)')
    assert missing == len(LEFT_OUT)
    assert unanswered.pop('rejected (bad input, see the encoder input status)') == \
        len(BAD_AFTER)
    assert stats['published'] + sum(unanswered.values()) + len(BAD_AFTER) == sent
    assert 'not answered' in line
