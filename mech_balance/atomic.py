"""
Atomic file writes: a target is replaced by a complete file or not touched at all.

Every file the package writes (balanced scenes, recordings, reports) is written to a
temporary file in the target's directory, named ``.NAME.partial-XXXXXXXX`` so that it is
recognisably incomplete, flushed to disk (``fsync``) and renamed over the target
(``os.replace``, atomic on POSIX) only once it is complete; the directory is then synced so
that the rename survives a power loss.  On an exception the temporary file is removed and
an existing target keeps its bytes; a process killed by SIGKILL may leave a ``.partial``
file next to the target, never a truncated target.

Three ways in: :func:`write_text_atomic` and :func:`write_bytes_atomic` for data in memory,
:func:`atomic_path` (a context manager yielding the temporary path) for writers that want a
path, and :func:`partial_path` / :func:`commit` / :func:`discard` for a writer whose file
outlives one block (the rig node's live recording).
"""

from contextlib import contextmanager
import os
from pathlib import Path
import tempfile

PARTIAL_MARK = '.partial-'
"""What the name of a temporary file contains: ``.NAME.partial-XXXXXXXX``."""
DEFAULT_MODE = 0o666
"""Permissions of a new file before the umask (as ``open(path, 'w')`` gives)."""


def partial_path(path):
    """
    Create and return an empty temporary file next to ``path``: ``.NAME.partial-XXXXXXXX``.

    Its permissions are those of an existing target, else :data:`DEFAULT_MODE` less the
    umask.  Hand it to :func:`commit` when complete or to :func:`discard` on failure.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}{PARTIAL_MARK}')
    try:
        os.fchmod(fd, _mode_for(path))
    finally:
        os.close(fd)
    return Path(tmp)


def commit(tmp, path):
    """Flush ``tmp`` to disk and rename it over ``path``; sync the directory."""
    with open(tmp, 'rb+') as f:
        os.fsync(f.fileno())
    os.replace(tmp, path)
    _fsync_dir(Path(path).parent)


def discard(tmp):
    """Remove a temporary file (no error if it is already gone)."""
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


@contextmanager
def atomic_path(path):
    """
    Yield a temporary path in the directory of ``path``; rename it over ``path`` on success.

    ``with atomic_path('good.rrd') as tmp: writer.save(tmp)``: on a clean exit the complete
    file replaces ``path`` (:func:`commit`); on any exception it is removed
    (:func:`discard`) and ``path`` is untouched.
    """
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


def _mode_for(path):
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        return DEFAULT_MODE & ~_umask()


def _umask():
    """Return the process umask without changing it (os.umask would race other threads)."""
    try:
        with open('/proc/self/status') as f:
            for line in f:
                if line.startswith('Umask:'):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    return 0o022


def _fsync_dir(directory):
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:  # a platform without directory file descriptors
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
