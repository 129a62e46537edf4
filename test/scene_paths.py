"""The paths into a scene's YAML mapping that the fuzz tests mutate (one home for both)."""


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
