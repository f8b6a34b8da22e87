"""Thread limits for numeric libraries inside partcal's many small computations.

A blend or a GP search makes many small matrix products, and a k-means
partition many small passes over a few hundred points. OpenBLAS and
OpenMP split each over every core, which costs more than it saves; on a
busy machine, or beside another fit in a second process, every call then
waits for threads that are not scheduled (small products and a k-means of
a few hundred joint configurations were measured tens of times slower on
two busy cores).
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

_CONTROLLERS: list = []       # one threadpoolctl controller, made on first use


def _controller() -> ThreadpoolController:
    if not _CONTROLLERS:
        _CONTROLLERS.append(ThreadpoolController())
    return _CONTROLLERS[0]


def one_blas_thread():
    """Context in which BLAS runs on one thread."""
    return _controller().limit(limits=1, user_api="blas")


def one_openmp_thread():
    """Context in which OpenMP code (scikit-learn's k-means) runs on one thread."""
    return _controller().limit(limits=1, user_api="openmp")
