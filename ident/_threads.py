"""Run numerical kernels with single-threaded BLAS.

Identification solves many least-squares problems with a handful of columns; OpenBLAS's thread
pool costs more than it saves on those (measured: a modal fit ran 6x slower with two threads than
with one on the two-core reference machine). The limit applies only inside the decorated call.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

P = ParamSpec("P")
R = TypeVar("R")


def single_threaded_blas(func: Callable[P, R]) -> Callable[P, R]:
    """Decorate ``func`` so that BLAS and LAPACK use one thread while it runs."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper
