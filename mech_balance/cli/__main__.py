"""
Run ``python -m mech_balance.cli``, the ``mech-balance`` command.

The same entry point as the console script.
"""

import sys

from mech_balance.cli.main import main

sys.exit(main())
