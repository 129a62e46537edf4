"""
The BLAS thread pool of the package's own processes (``mech-balance`` and ``rig_node``).

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
    numpy's default pool is kept, which is only slower).
    """
    n = blas_threads(environ)
    if n is None:
        return None
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return None
    # threadpoolctl reaches the libraries loaded so far: load numpy's and scipy's OpenBLAS
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    threadpool_limits(limits=n, user_api='blas')
    return n
