"""The commands' ``--json`` output: strict JSON, a non-finite number written as ``null``."""

import json
import math


def finite(obj):
    """Return ``obj`` with NaN and infinities (at any depth) as None: JSON has neither."""
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps(obj):
    """Return ``obj`` as strict, indented JSON (non-finite numbers as ``null``)."""
    return json.dumps(finite(obj), indent=2, allow_nan=False)
