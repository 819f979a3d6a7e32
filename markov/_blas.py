"""One BLAS thread while the package's own kernels run.

The matrix-free products (rings, roads, sectors) are numba-parallel over every
core.  The Krylov and ARPACK loops around them call BLAS on vectors between
products, and OpenBLAS threads keep spinning after each call: on 2 cores they
took the cores from the product (a vmax 2 road L = 16: 60 ms a product inside
BiCGSTAB against 35 ms alone; the spectrum of the ring L = 16, N = 8, vmax 2,
every sector: 20 s against 2.4 s).  A level-1 or level-2 operation on one
vector gains nothing from a second thread, so these loops run on one
(``threadpoolctl``); dense factorisations elsewhere keep every thread.
"""
from __future__ import annotations

__all__ = ["one_blas_thread"]


def one_blas_thread():
    """A context manager holding BLAS to one thread (threadpoolctl), restored on exit.

    Returns
    -------
    threadpoolctl.threadpool_limits
        Use as ``with one_blas_thread(): ...``.
    """
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")
