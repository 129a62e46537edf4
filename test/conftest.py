"""
Test-session set-up: numpy's BLAS pool limited as by the package's entry points.

The suite's process limits it as :mod:`mech_balance.threads` does, so that a loaded CI
machine does not stall the small LAPACK calls of the tests that call the library directly.
"""

from mech_balance import threads

threads.limit_blas_threads()
