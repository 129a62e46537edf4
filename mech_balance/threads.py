"""
The BLAS thread pool and glibc's allocator of the package's processes: one home for both.

:func:`settle_allocator`, :func:`return_large_blocks`, :func:`limit_blas_threads`;
measurements and the environment variables that win: docs/core.md#threads-and-memory.
"""

import os

ENV = 'MECH_BALANCE_BLAS_THREADS'
"""Environment variable: BLAS threads of the package's processes (an integer >= 1)."""
USER_VARS = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')
"""BLAS settings of the user's environment that are respected as they are."""
DEFAULT_THREADS = 1
"""BLAS threads unless chosen otherwise: the package's matrices are small."""


def blas_threads(environ=None):
    """Return the BLAS thread count to use, or None (ValueError naming :data:`ENV` if bad)."""
    environ = os.environ if environ is None else environ
    text = environ.get(ENV)
    if text is None:
        return None if any(v in environ for v in USER_VARS) else DEFAULT_THREADS
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f'{ENV}: got {text!r}, expected an integer >= 1 (BLAS threads)')
    return n


def limit_blas_threads(environ=None):
    """
    Limit numpy's BLAS pool to :func:`blas_threads`; return the limit, or None if left alone.

    A BLAS loaded later (scipy's) and child processes get the limit through
    ``OPENBLAS_NUM_THREADS``, which this call sets.
    """
    n = blas_threads(environ)
    if n is None or os.environ.get('OPENBLAS_NUM_THREADS') == str(n):   # none, or set already
        return n
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return None
    # threadpoolctl reaches the libraries loaded so far (numpy's OpenBLAS); one loaded later
    # (scipy's, imported only by what uses it) reads OPENBLAS_NUM_THREADS as it loads
    import numpy  # noqa: F401
    os.environ['OPENBLAS_NUM_THREADS'] = str(n)
    threadpool_limits(limits=n, user_api='blas')
    return n


def release_memory():
    """Return the heap memory freed so far to the system (``malloc_trim``); True if done."""
    import ctypes
    import ctypes.util
    try:
        ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6').malloc_trim(0)
        return True
    except (OSError, AttributeError):
        return False


ALLOCATOR_SETTLE_BYTES = 8 * 2 ** 20
"""Size of the block :func:`settle_allocator` allocates and frees once per process."""
_ALLOCATOR = {'settled': False, 'fixed': False}


def settle_allocator():
    """Allocate and free 8 MiB once per process: glibc then reuses large temporaries."""
    if not (_ALLOCATOR['settled'] or _ALLOCATOR['fixed']):
        import numpy   # (on first use: the command line parsers need none)
        _ALLOCATOR['settled'] = True
        numpy.empty(ALLOCATOR_SETTLE_BYTES, dtype=numpy.uint8)   # freed at once


MMAP_THRESHOLD_BYTES = 128 * 1024
"""Blocks from this size up are mapped and unmapped by the kernel in the rig node."""
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def return_large_blocks(threshold=MMAP_THRESHOLD_BYTES):
    """Fix glibc's mmap threshold for this process (bounded memory); return True if set."""
    import ctypes
    import ctypes.util
    if 'MALLOC_MMAP_THRESHOLD_' in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6')
        ok = libc.mallopt(_M_MMAP_THRESHOLD, int(threshold))
        libc.mallopt(_M_TRIM_THRESHOLD, 2 * int(threshold))
        _ALLOCATOR['fixed'] = bool(ok)
        return bool(ok)
    except (OSError, AttributeError):
        return False
