"""Which backend factorizes a completion's derivative array: chosen here, and only here, with the reason kept.

The backends and the rule every fast path keeps (return what the path below would, or decline) are those of
`lsc._factors`. This module takes the decisions:

- `setup`: at construction. Constant coefficients: the structured set-up (`lsc._structured`) when asked
  (``setup='auto'``) and the maps are the library's own; the SVD of the whole array when it declines, with
  its reason (`Completion.setup_note`). Time-varying: the SVD at the reference time (the rank every later
  time must keep).
- `factors_at`: one time of a time-varying completion: the block-column QR when asked (``block_qr``), else
  the LU warm-started from the last time factorized (``warm_start``, arrays of `WARM_MIN_ROWS` rows or
  more), else the SVD.
- `factors_many`, `stacked`: several times at once (`stackable` completions): the SVDs stacked; the times
  left out are the caller's to take one at a time.
"""

import numpy as np

from ._dense_factors import WARM_MIN_ROWS, DenseFactors
from ._factors import Decline
from . import _index
from ._structured import StructuredFactors
from ._validate import check_k

__all__ = ["factors_at", "factors_many", "setup", "stackable", "stacked"]


def setup(completion, kind, k):
    """``(k, factors, maps, kind, note)`` at construction (`maps`: ``(G, W)`` for constant coefficients).

    `kind`: 'auto' or 'dense' (checked here). The structured set-up is tried for constant coefficients
    and the library's own maps; where it declines (a rank decision it cannot make as safely, in its index
    determination or in the maps) `note` says why and the dense path decides.
    """
    if kind not in ("auto", "dense"):
        raise ValueError(f"`setup` must be 'auto' or 'dense'; found {kind!r}.")
    eq, t, q, rcond = completion._eq, completion._t_ref, completion.extra_order, completion.rcond
    constant, fac, note = eq.is_constant, None, None
    if kind == "auto" and constant and completion._builtin:
        try:
            fac = StructuredFactors(eq.A(t), eq.B(t), None if k is None else check_k(k), q, rcond)
            if k is not None and k > _index.K_ABOVE_INDEX + fac.index:
                fac = None  # far above the index: the dense path's refusal, with its message
            else:
                return fac.k, fac, completion._maps(fac, completion._lam_jets(fac.t, fac.k)), "structured", None
        except Decline as exc:
            note = f"structured set-up declined: {exc}"
    k = _index.decide_k(completion.dae, k, t, completion.t_span, rcond) if fac is None else fac.k
    if constant:
        fac = DenseFactors.at(eq, k, t, q, rcond)
        return k, fac, completion._maps(fac, completion._lam_jets(fac.t, k)), "dense", note
    # time-varying: the forcing at the reference time is evaluated (and refused) here, as at every later time
    return k, DenseFactors.at(eq, k, t, q, rcond, fstack=eq.f_jet(t, k + q)), None, "dense", note


def factors_at(completion, t, fstack=None):
    """The dense factors at one time `t` (`fstack`: the forcing jet there, or None for maps), checked against
    the completion's rank; the warm start reads (and updates) ``completion._last_factors``."""
    ref = completion._last_factors if completion.warm_start else None
    fac = DenseFactors.at(completion._eq, completion.k, t, completion.extra_order, completion.rcond, fstack=fstack,
                          expected_rank=completion._rank, reference=ref,
                          block=completion.block_qr and completion.warm_start)
    if fac.Z2.shape[1] >= WARM_MIN_ROWS:
        completion._last_factors = fac
    return fac


def stackable(completion):
    """Whether `factors_many` may stack `completion`'s evaluations: time-varying, the library's own maps, no
    column equilibration, arrays under `WARM_MIN_ROWS` rows (larger ones are factorized one at a time)."""
    n, r = completion.n, completion._rank
    return (not completion.dae.is_constant and completion._builtin and completion._scaling.c is None
            and 0 < r < (completion.k + 1) * n < WARM_MIN_ROWS)


def factors_many(completion, ts, values=True):
    """``(factors or None, kept)``: the stacked SVD factors at the times of `ts` (indices `kept`) that decide
    their rank clearly. A time whose coefficients or forcing raise is left out too (the one-time path raises
    it, with its message). `values`: the forcing as values at each time (else as maps)."""
    eq, k, q, n = completion._eq, completion.k, completion.extra_order, completion.n
    order = k + q
    kept, fstacks, A, B = [], [], [], []
    for i, t in enumerate(ts):
        try:  # in the one-time path's order: the forcing's jet, then the coefficients'
            fstack = eq.f_jet(t, order) if values else None
            Aj, Bj = eq.A.jet(t, order), eq.B.jet(t, order)
        except Exception:  # noqa: BLE001 - the one-time path raises it, with its message
            continue
        kept.append(i)
        fstacks.append(fstack)
        A.append(Aj)
        B.append(Bj)
    if len(kept) < 2:
        return None, np.zeros(0, dtype=int)
    fac, good = DenseFactors.many(np.stack(A, axis=1), np.stack(B, axis=1), k, q, [ts[i] for i in kept],
                                  completion.rcond, completion._rank, np.array(fstacks) if values else None)
    return fac, np.array(kept, dtype=int)[good]


def stacked(completion, ts, values=True):
    """``[(G, W, C, Wc) or None]``: the completion at the times of `ts` the stacked factors decide, in the given
    unknowns (None at the others, which the caller evaluates one at a time)."""
    out = [None] * len(ts)
    if len(ts) < 2 or not stackable(completion):
        return out
    fac, kept = factors_many(completion, ts, values)
    if fac is None:
        return out
    try:
        G, W = completion._given(*completion._maps(fac, completion._lam_jets(fac.t)), fac)
    except (np.linalg.LinAlgError, ValueError):  # the one-time path decides, and says why
        return out
    given, Wc = completion._given_factors(fac)
    for j, i in enumerate(kept):
        if np.all(np.isfinite(G[j])):  # NaN: a time the factors left undecided
            out[i] = (G[j], W[j], given.C[j], Wc[j])
    return out
