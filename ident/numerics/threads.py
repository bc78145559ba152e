"""Run numerical kernels with single-threaded BLAS.

Identification solves many least-squares problems with a handful of columns; OpenBLAS's thread
pool costs more than it saves on those (measured: a modal fit ran 6x slower with two threads than
with one on the two-core reference machine). The limit applies only inside the decorated call.

Setting the limit is not free: ``threadpool_limits`` finds the loaded BLAS libraries anew on
every entry (a few milliseconds, measured 2-6 ms). A decorated call made inside another one
(``e2rfc.identify`` fitting the modes of every release) is already limited, so only the
outermost call of each thread sets the limit.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import ParamSpec, TypeVar

from threadpoolctl import threadpool_limits

P = ParamSpec("P")
R = TypeVar("R")

#: Per thread: how many decorated calls are running (the limit is per process, the nesting per
#: thread: a thread entering on its own sets the limit itself).
_depth = threading.local()


def single_threaded_blas(func: Callable[P, R]) -> Callable[P, R]:
    """Decorate ``func`` so that BLAS and LAPACK use one thread while it runs."""

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        depth = getattr(_depth, "value", 0)
        if depth:
            _depth.value = depth + 1
            try:
                return func(*args, **kwargs)
            finally:
                _depth.value = depth
        with threadpool_limits(limits=1, user_api="blas"):
            _depth.value = 1
            try:
                return func(*args, **kwargs)
            finally:
                _depth.value = 0

    return wrapper
