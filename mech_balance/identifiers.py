"""Names given as text (frames, joints, lists of links), checked one way everywhere."""

import re

from mech_balance.conventions import MAX_NAME_LENGTH

FRAME_ID = re.compile(r'[A-Za-z_][A-Za-z0-9_/]*')
"""A TF frame name: letters, digits, '_' and '/', not starting with '/' or a digit."""
NAME = re.compile(r'[A-Za-z0-9_][A-Za-z0-9_.\-/]*')
"""A joint or link name: letters, digits, '_', '.', '-', '/'; no space, no markup."""
MAX_LIST_LENGTH = 64 * MAX_NAME_LENGTH
"""Longest comma-separated list of names accepted, characters."""


def _show(value):
    text = repr(value)
    return text if len(text) <= 80 else f'{text[:80]}... ({len(text)} characters)'


def _length(value, field):
    if not isinstance(value, str):
        raise ValueError(f'{field}: got {_show(value)}, expected text')
    if len(value) > MAX_NAME_LENGTH:
        raise ValueError(f'{field}: got a name of {len(value)} characters, expected at most '
                         f'{MAX_NAME_LENGTH} (a fixed limit of mech_balance)')


def check_frame_id(value, field='frame_id'):
    """Return ``value`` if it is a TF frame name of at most MAX_NAME_LENGTH characters."""
    _length(value, field)
    if not FRAME_ID.fullmatch(value):
        raise ValueError(f'{field}: got {_show(value)}, expected a frame name of letters, '
                         "digits, '_' and '/', not starting with '/' or a digit (e.g. "
                         'rig_frame)')
    return value


def check_name(value, field, allow_empty=False):
    """Return ``value`` if it is a joint or link name (or empty, if ``allow_empty``)."""
    _length(value, field)
    if allow_empty and value == '':
        return value
    if not NAME.fullmatch(value):
        raise ValueError(f'{field}: got {_show(value)}, expected a name of letters, digits, '
                         "'_', '.', '-' and '/' (no spaces or markup)" +
                         (', or empty' if allow_empty else ''))
    return value


def split_names(text):
    """Return the names of a comma-separated list (empty text: none)."""
    return [n.strip() for n in text.split(',')] if text.strip() else []


def check_name_list(text, field):
    """Return the names of a comma-separated list, each a valid name given once."""
    if not isinstance(text, str):
        raise ValueError(f'{field}: got {_show(text)}, expected comma-separated names')
    if len(text) > MAX_LIST_LENGTH:
        raise ValueError(f'{field}: got a list of {len(text)} characters, expected at most '
                         f'{MAX_LIST_LENGTH}')
    names = split_names(text)
    for name in names:
        if not name:
            raise ValueError(f'{field}: got {_show(text)}, expected comma-separated link '
                             'names such as "crank,rocker" (or empty), no empty one')
        check_name(name, field)
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ValueError(f'{field}: got {twice[0]!r} twice in {_show(text)}, expected each '
                         'link once')
    return names
