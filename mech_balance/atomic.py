"""
Atomic file writes: a target is replaced by a complete file or not touched at all.

Ways in: :func:`write_text_atomic`, :func:`write_bytes_atomic`, :func:`atomic_path`, and
:func:`partial_path` / :func:`commit` / :func:`discard` for a file that outlives one block;
how the files are synced, listed and logged: docs/core.md#module-overviews.
"""

import collections
from contextlib import contextmanager, suppress
import os
from pathlib import Path
import signal
import tempfile
import threading

PARTIAL_MARK = '.partial-'
"""What the name of a temporary file contains: ``.NAME.partial-XXXXXXXX``."""
DEFAULT_MODE = 0o666
"""Permissions of a new file before the umask (as ``open(path, 'w')`` gives)."""

_lock = threading.Lock()
_pending = set()      # temporary files neither committed nor discarded
_log = collections.deque(maxlen=64)   # (sequence number, 'written' or 'discarded', target)
_count = [0]          # commits and discards so far
_held = {'depth': 0, 'deferred': None}   # the main thread's held block (_signals_held)


def partial_path(path):
    """Create and return an empty ``.NAME.partial-XXXXXXXX`` next to ``path`` (its permissions)."""
    path = Path(path)
    with _signals_held():
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}{PARTIAL_MARK}')
        with _lock:
            _pending.add(Path(tmp))
    try:
        os.fchmod(fd, _mode_for(path))
    finally:
        os.close(fd)
    return Path(tmp)


def commit(tmp, path):
    """Flush ``tmp`` to disk and rename it over ``path``; sync the directory."""
    with open(tmp, 'rb+') as f:
        os.fsync(f.fileno())
    with _signals_held():   # renamed and logged as written, or neither
        os.replace(tmp, path)
        _note(tmp, 'written', path)
    _fsync_dir(Path(path).parent)


def discard(tmp):
    """Remove a temporary file (no error if it is already gone)."""
    with suppress(FileNotFoundError):
        os.unlink(tmp)
    _note(tmp, 'discarded', target_of(tmp))


def _note(tmp, what, target):
    with _lock:
        if Path(tmp) in _pending:
            _pending.discard(Path(tmp))
            _count[0] += 1
            _log.append((_count[0], what, Path(target)))


def discard_pending():
    """Remove every temporary file not yet committed or discarded; return their paths."""
    with _lock:
        pending = sorted(_pending)
    for tmp in pending:
        discard(tmp)
    return pending


def target_of(tmp):
    """Return the target a temporary file of :func:`partial_path` was made for."""
    tmp = Path(tmp)
    return tmp.parent / tmp.name[1:].rpartition(PARTIAL_MARK)[0]


def write_count():
    """Return how many temporary files were committed or discarded so far (a mark)."""
    with _lock:
        return _count[0]


def written_since(mark):
    """Return the targets committed after :func:`write_count` returned ``mark``."""
    with _lock:
        return [path for n, what, path in _log if n > mark and what == 'written']


def discarded_since(mark):
    """Return the targets whose temporary file was discarded after ``mark`` (not written)."""
    with _lock:
        return [path for n, what, path in _log if n > mark and what == 'discarded']


@contextmanager
def atomic_path(path):
    """Yield a temporary path next to ``path``; rename it over ``path`` on success."""
    tmp = partial_path(path)
    try:
        yield tmp
        commit(tmp, path)
    except BaseException as exc:
        discard(tmp)
        if isinstance(exc, OSError) and exc.filename is None:
            exc.filename = str(path)  # 'File too large' alone does not say which file
        raise


def write_bytes_atomic(path, data):
    """Write ``data`` (bytes) to ``path`` atomically (this module's docstring)."""
    with atomic_path(path) as tmp:
        with open(tmp, 'wb') as f:
            f.write(data)


def write_text_atomic(path, text, encoding='utf-8'):
    """Write ``text`` to ``path`` atomically, encoded as ``encoding`` (UTF-8)."""
    write_bytes_atomic(path, text.encode(encoding))


@contextmanager
def _signals_held():
    """Hold SIGINT and SIGTERM (handlers that call :func:`defer_signal`) in the main thread."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _held['depth'] += 1
    try:
        yield
    finally:
        _held['depth'] -= 1
        if _held['depth'] == 0 and _held['deferred']:
            signum, _held['deferred'] = _held['deferred'], None
            signal.raise_signal(signum)


def defer_signal(signum):
    """For a signal handler: return True if ``signum`` is held back (then return at once)."""
    if _held['depth'] > 0:
        _held['deferred'] = _held['deferred'] or signum
        return True
    return False


def _mode_for(path):
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        return DEFAULT_MODE & ~_umask()


def _umask():
    """Return the process umask without changing it (os.umask would race other threads)."""
    with suppress(OSError, ValueError, IndexError), open('/proc/self/status') as f:
        for line in f:
            if line.startswith('Umask:'):
                return int(line.split()[1], 8)
    return 0o022


def _fsync_dir(directory):
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # a platform without directory file descriptors
        return
    try:
        with suppress(OSError):
            os.fsync(fd)
    finally:
        os.close(fd)
