"""Output files: the one check every writer runs before it computes anything."""

import os
from pathlib import Path
import re
import tempfile


def check_output_path(path, field, suffixes, create_dir=False):
    """
    Return the output file ``path`` as a ``Path``, checked before anything is computed.

    It must end in one of ``suffixes`` and be writable, in an existing directory that accepts a
    new file (``create_dir=True``: created, for a command that documents it).  Raises
    ``ValueError`` naming ``field``.
    """
    text = str(path)
    path = Path(text).expanduser()
    if path.suffix.lower() not in suffixes:
        raise ValueError(f'{field}: got {text!r}, expected a file name ending in '
                         + ' or '.join(suffixes))
    if path.is_dir():
        raise ValueError(f'{field}: got {text!r}, a directory, expected a file name ending in '
                         + ' or '.join(suffixes))
    directory = path.parent
    if not directory.is_dir():
        if not create_dir:
            raise ValueError(f'{field}: got {text!r}, its directory {str(directory)!r} does '
                             'not exist, expected a file in an existing directory')
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f'{field}: got {text!r}, its directory {str(directory)!r} cannot '
                             f'be created ({exc.strerror})') from None
    try:  # the directory accepts a new file (permissions, read-only mounts, quotas)
        with tempfile.NamedTemporaryFile(dir=directory, prefix='.mech-balance-probe-'):
            pass
    except OSError as exc:
        raise ValueError(f'{field}: got {text!r}, its directory {str(directory)!r} is not '
                         f'writable ({exc.strerror}), expected a directory this process can '
                         'write in') from None
    if path.exists() and not os.access(path, os.W_OK):
        raise ValueError(f'{field}: got {text!r}, an existing file that is not writable, '
                         'expected a path this process can write')
    return path


VIEWER_URL = re.compile(r'rerun(\+https?)?://[A-Za-z0-9_.\-\[\]:]+/proxy')
"""A running rerun viewer's gRPC address (``rerun`` prints it when it starts)."""


def check_viewer_url(url, field):
    """Return ``url`` if it is a rerun viewer's gRPC address, else raise ValueError."""
    if not isinstance(url, str) or not VIEWER_URL.fullmatch(url):
        raise ValueError(f'{field}: got {url!r}, expected a rerun viewer address such as '
                         "'rerun+http://127.0.0.1:9876/proxy' (what `rerun` prints when it "
                         'starts)')
    return url
