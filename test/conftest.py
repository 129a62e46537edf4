"""
Test-session set-up: the suite's process limits numpy's BLAS pool as the package's entry
points do (:mod:`mech_balance.threads`), so a loaded CI machine does not stall the small
LAPACK calls of the tests that call the library directly.
"""

from mech_balance import threads

threads.limit_blas_threads()
