"""ident.numerics.threads.single_threaded_blas: one BLAS thread inside, nested calls set it once."""

from __future__ import annotations

import numpy as np  # noqa: F401  (loads the BLAS library the tests look at)
from threadpoolctl import threadpool_info, threadpool_limits

from ident.numerics.threads import single_threaded_blas


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


@single_threaded_blas
def _inner() -> list[int]:
    return _blas_threads()


@single_threaded_blas
def _outer() -> tuple[list[int], list[int], list[int]]:
    before = _blas_threads()
    inside = _inner()
    return before, inside, _blas_threads()


def test_nested_calls_run_single_threaded_and_the_limit_is_restored():
    with threadpool_limits(limits=2, user_api="blas"):
        outside = _blas_threads()
        assert outside and all(n == 2 for n in outside)  # numpy's BLAS is loaded and limited
        before, inside, after = _outer()
        assert all(n == 1 for n in before + inside + after)
        # The nested call left the outer one's limit in place, and leaving the outer call
        # restored the caller's.
        assert _blas_threads() == outside
        assert _inner() == [1] * len(outside)
        assert _blas_threads() == outside


def test_an_exception_inside_leaves_the_nesting_count_clean():
    @single_threaded_blas
    def failing() -> None:
        _inner()
        raise RuntimeError("boom")

    with threadpool_limits(limits=2, user_api="blas"):
        outside = _blas_threads()
        try:
            failing()
        except RuntimeError:
            pass
        else:  # pragma: no cover - the call must raise
            raise AssertionError("failing() did not raise")
        assert _blas_threads() == outside
        # A later outermost call sets the limit again (the count went back to zero).
        assert _inner() == [1] * len(outside)
