"""
The BLAS thread pool and glibc's allocator of the package's processes: one home for both.

glibc's allocator, one policy, set here and nowhere else
    Computing favours speed: the first linkage a process builds (planar or spatial) calls
    :func:`settle_allocator`, which lets glibc raise its mmap threshold once, so that a
    cycle's larger temporaries are reused from the heap instead of being mapped afresh at
    every call.  The one exception is the long-running rig node, which favours bounded
    memory: its ``main`` calls :func:`return_large_blocks` before anything is computed,
    fixing the threshold at :data:`MMAP_THRESHOLD_BYTES` (large temporaries go back to the
    kernel at free), and :func:`settle_allocator` then does nothing.  ``MALLOC_*`` settings
    in the environment win over both.  :func:`release_memory` returns freed heap memory to
    the system after a large one-off computation.

The BLAS pool of ``mech-balance`` and ``rig_node``

numpy's OpenBLAS starts one thread per core and hands every LAPACK call to them, also the
package's small ones (identification's 4096 x 19 QR reductions, the cone programs' factors).
On a busy machine those threads wait for cores: measured on the 2-core development machine
at load average 4.5, one such QR took 35 ms with the default pool against 1.0 ms with one
thread, and ``~/identify`` on 84 000 samples spent 1.9 s of its 2.5 s in them.  The entry
points therefore limit the pool to :data:`DEFAULT_THREADS` (through ``threadpoolctl``, at run
time, whatever imported numpy first), unless the user chose: ``MECH_BALANCE_BLAS_THREADS``
sets the count, and an ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` or ``MKL_NUM_THREADS``
in the environment is left to take effect as set.
"""

import os

ENV = 'MECH_BALANCE_BLAS_THREADS'
"""Environment variable: BLAS threads of the package's processes (an integer >= 1)."""
USER_VARS = ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS')
"""BLAS settings of the user's environment that are respected as they are."""
DEFAULT_THREADS = 1
"""BLAS threads unless chosen otherwise: the package's matrices are small."""


def blas_threads(environ=None):
    """
    Return the BLAS thread count the package's processes use, or None to leave it alone.

    Raises ValueError naming :data:`ENV` and its value when it is not an integer >= 1.
    """
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
    Limit numpy's BLAS pool to :func:`blas_threads`; return the limit set, or None.

    None when the environment leaves the pool alone or ``threadpoolctl`` is missing (then
    numpy's default pool is kept, which is only slower).  A BLAS loaded later (scipy's) and
    child processes get the limit through ``OPENBLAS_NUM_THREADS``, which this call sets.
    """
    n = blas_threads(environ)
    if n is None:
        return None
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
    """
    Return the heap memory freed so far to the system (glibc's ``malloc_trim``); True if done.

    A long-running node that runs a large computation now and then (``~/identify`` on two
    minutes of 1 kHz data) otherwise keeps its peak resident: glibc keeps freed blocks in the
    per-thread arenas of the executor's threads.  Measured: three identifications of 100 s of
    1 kHz data on a thread each left the process 26 MB larger; after this call, 31 MB
    smaller than before them.  A no-op (False) where the C library has no ``malloc_trim``.
    """
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
    """
    Allocate and free one 8 MiB block, once per process, before the first cycle.

    glibc's malloc serves blocks above its mmap threshold (128 KiB at start) straight from
    the kernel and returns them at ``free``, and it trims the top of its heap beyond twice
    that threshold: a cycle's larger temporaries (a 40-link chain's complex ``(39, 360)``
    stacks are 225 KiB) would then be page-faulted in afresh at every call (about a third
    of that chain's cycle).  Freeing a block from the kernel raises both thresholds to its
    size (glibc's documented dynamic threshold, ``mallopt(3)``), so the temporaries are
    reused from the heap.  Does nothing after :func:`return_large_blocks` (the node's
    policy) or where ``MALLOC_MMAP_THRESHOLD_`` and the like switch that adjustment off.
    Nothing is committed (the block is never touched).
    """
    if not (_ALLOCATOR['settled'] or _ALLOCATOR['fixed']):
        import numpy   # (on first use: the command line parsers need none)
        _ALLOCATOR['settled'] = True
        numpy.empty(ALLOCATOR_SETTLE_BYTES, dtype=numpy.uint8)   # freed at once


MMAP_THRESHOLD_BYTES = 128 * 1024
"""Blocks from this size up are mapped and unmapped by the kernel in the rig node (glibc's
initial default, kept fixed: see :func:`return_large_blocks`)."""
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3


def return_large_blocks(threshold=MMAP_THRESHOLD_BYTES):
    """
    Fix glibc's mmap threshold for this process; return True if set.

    glibc raises its threshold to the size of every mapped block freed (up to 32 MB), after
    which numpy's large temporaries live in the heaps of the threads that made them and stay
    resident.  A long-running node that now and then computes on large arrays pays that in
    memory: ``bench --section identify_stamps`` grew the node by 52 MB against its 46 MB
    bound with the dynamic threshold, 32 MB with it fixed (the temporaries of ``~/identify``
    returned at free).  Setting ``MALLOC_MMAP_THRESHOLD_`` in the environment does the same
    and is left alone; a no-op (False) where the C library has no ``mallopt``.
    """
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
