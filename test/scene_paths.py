"""The paths into a scene's YAML mapping and the numbers in a report: the fuzz tests' helpers."""


def paths(node, prefix=()):
    """Yield the path (a tuple of keys and indices) of every value below ``node``."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield prefix + (k,)
            yield from paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield prefix + (i,)
            yield from paths(v, prefix + (i,))


def get(data, path):
    """Return the value at ``path`` in ``data``."""
    for key in path:
        data = data[key]
    return data


def is_number(value):
    """Return whether ``value`` is an int or a float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def numbers(obj):
    """Yield every number of a nested mapping or sequence."""
    if isinstance(obj, dict):
        for v in obj.values():
            yield from numbers(v)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from numbers(v)
    elif is_number(obj):
        yield obj
