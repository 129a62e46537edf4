"""Between two bench sections: wait for the machine to settle, and judge the printed verdicts."""

import os
import re
import sys
import time

SETTLE_TIMEOUT_S = 30.0
"""The longest wait for the machine to settle before a section (then it is said as such)."""
SETTLE_BUSY_SHARE = 0.5
"""Settled: the whole machine's CPU is busy at most this share of one sampling window."""
SETTLE_WINDOW_S = 1.0
"""The sampling window of the CPU's busy share."""
FAIL_VERDICT = re.compile(r'\bFAIL\b')
"""A section's failed target, as every section prints it (``-> FAIL``, ``FAIL:``)."""


def _cpu_times():
    """Return (busy, total) jiffies of all CPUs (/proc/stat), or None where it is missing."""
    try:
        with open('/proc/stat') as f:
            fields = [int(x) for x in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)   # idle + iowait
    return sum(fields) - idle, sum(fields)


def busy_share(window_s=SETTLE_WINDOW_S):
    """Return the share of all CPUs busy over the next ``window_s`` seconds (None: unknown)."""
    first = _cpu_times()
    time.sleep(window_s)
    second = _cpu_times()
    if first is None or second is None or second[1] == first[1]:
        return None
    return (second[0] - first[0]) / (second[1] - first[1])


def stat_fields(pid):
    """Return the fields of /proc/PID/stat after the command name (``state`` first)."""
    with open(f'/proc/{pid}/stat') as f:
        return f.read().rpartition(')')[2].split()   # the command may hold spaces and ')'


def children():
    """Return the process ids whose parent is this process (/proc; empty where missing)."""
    me, out = os.getpid(), []
    try:
        pids = [p for p in os.listdir('/proc') if p.isdigit()]
    except OSError:
        return out
    for pid in pids:
        try:
            ppid = int(stat_fields(pid)[1])
        except (OSError, ValueError, IndexError):
            continue
        if ppid == me:
            out.append(int(pid))
    return out


def settle(timeout_s=SETTLE_TIMEOUT_S, clock=time.monotonic):
    """
    Wait until no child is left and the CPU is at most SETTLE_BUSY_SHARE busy; say how it went.

    Returns one line: the wait, busy share, load average and whether it settled in ``timeout_s``.
    """
    start = clock()
    share = None
    while True:
        left = children()
        share = busy_share()
        waited = clock() - start
        calm = not left and share is not None and share <= SETTLE_BUSY_SHARE
        if calm or waited >= timeout_s:
            break
    load = os.getloadavg()[0] if hasattr(os, 'getloadavg') else float('nan')
    busy = 'unknown' if share is None else f'{share * 100:.0f} %'
    state = 'settled' if calm else (f'not settled after {timeout_s:g} s ('
                                    f'{len(left)} child processes left; the figures below '
                                    'are upper bounds)')
    return (f'[{state}: waited {waited:.1f} s; CPU busy {busy} over {SETTLE_WINDOW_S:g} s, '
            f'load average {load:.2f}]')


def failures(text):
    """Return the lines of printed bench tables that hold a FAIL verdict."""
    return [line.strip() for line in text.splitlines() if FAIL_VERDICT.search(line)]


def report_failures(command, printed):
    """List the FAIL lines of the ``printed`` tables on stderr; return whether there are any."""
    failed = failures('\n'.join(printed))
    if failed:
        print(f'{command}: {len(failed)} target(s) FAILED:', file=sys.stderr)
        for line in failed:
            print(f'  {line}', file=sys.stderr)
    return bool(failed)
