"""
Run ``python -m mech_balance.cli``, the ``mech-balance`` command.

SIGINT or SIGTERM while the modules load end the process quietly with 128 + the signal.
"""

import os
import signal
import sys


def _quit(signum, frame):
    os._exit(128 + signum)


for _signum in (signal.SIGINT, signal.SIGTERM):
    if signal.getsignal(_signum) is not signal.SIG_IGN:   # a background job's stays ignored
        signal.signal(_signum, _quit)

from mech_balance.cli.main import main  # noqa: E402 (after the handlers)

sys.exit(main())
