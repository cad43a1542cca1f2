"""The set-ups' BLAS threads are chosen (lsc._threads), not inherited, and restored afterwards."""
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import lsc
from lsc import gallery


def _blas_threads():
    return max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")


class Probe(lsc.AlternativeCompletion):
    """Records the BLAS thread count while the completion's maps are computed."""

    seen = []

    def _maps(self, fac, t):
        Probe.seen.append(_blas_threads())
        return super()._maps(fac, t)


def test_one_thread_during_the_set_up_then_restored(monkeypatch):
    monkeypatch.delenv("LSC_BLAS_THREADS", raising=False)
    with threadpool_limits(limits=2, user_api="blas"):  # what a caller's environment might hold
        assert _blas_threads() == 2
        Probe.seen.clear()
        lsc.complete(gallery.random_pencil(n=8, blocks=(3, 2), seed=1).dae, Probe, lam=1.0)
        assert Probe.seen and set(Probe.seen) == {1}
        assert _blas_threads() == 2


def test_environment_override(monkeypatch):
    monkeypatch.setenv("LSC_BLAS_THREADS", "2")
    with threadpool_limits(limits=1, user_api="blas"):
        Probe.seen.clear()
        lsc.complete(gallery.random_pencil(n=8, blocks=(3, 2), seed=1).dae, Probe, lam=1.0)
        assert set(Probe.seen) == {2}
        assert _blas_threads() == 1
    monkeypatch.setenv("LSC_BLAS_THREADS", "zero")
    with pytest.raises(ValueError, match="LSC_BLAS_THREADS must be a positive int"):
        lsc.complete(gallery.random_pencil(n=8, blocks=(3, 2), seed=1).dae, "alternative", lam=1.0)
