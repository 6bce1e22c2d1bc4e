"""Order statistics: grouped lower medians and weighted quantiles by radix selection, of
one set of values or of each group of them.

Arrays in, arrays out, no I/O; deterministic for any thread count.
"""
from __future__ import annotations


import numpy as np

from potflat._jit import leaf, parallel, prange


@leaf
def lower_medians(values, start, stop, out):
    """The lower median of each segment of ``values``: its element of rank ``ceil(k / 2) - 1``
    (from 0) among the segment's ``k`` values in ascending order (Hoare's selection on a copy).

    Parameters
    ----------
    values : (s,) float64
        No NaN.
    start, stop : (g,) int64
        Segment ``j`` is ``values[start[j]:stop[j]]`` (not empty).
    out : (g,) float64
        Output.
    """
    longest = 0
    for j in range(out.shape[0]):
        longest = max(longest, stop[j] - start[j])
    buf = np.empty(longest)
    for j in range(out.shape[0]):
        k = stop[j] - start[j]
        for q in range(k):
            buf[q] = values[start[j] + q]
        want = (k + 1) // 2 - 1
        lo = 0
        hi = k - 1
        while lo < hi:
            pivot = buf[(lo + hi) >> 1]
            a = lo
            b = hi
            while a <= b:
                while buf[a] < pivot:
                    a += 1
                while buf[b] > pivot:
                    b -= 1
                if a <= b:
                    t = buf[a]
                    buf[a] = buf[b]
                    buf[b] = t
                    a += 1
                    b -= 1
            if want <= b:
                hi = b
            elif want >= a:
                lo = a
            else:
                break
        out[j] = buf[want]


#: Key of a NaN in :func:`select_weighted_quantiles` (after every number, as NumPy sorts NaN last).
_NAN_KEY = np.uint64(0xFFFFFFFFFFFFFFFF)


_SIGN_BIT = np.uint64(0x8000000000000000)


#: Bits of the key sorted out per histogram pass, and the candidates below which the rest is sorted.
_RADIX_BITS = 16


_SORT_BELOW = 1 << 12


@leaf
def _order_key(bits):
    """Unsigned key of a float64's bits that orders as the numbers do (NaN last)."""
    if (bits & np.uint64(0x7FF0000000000000)) == np.uint64(0x7FF0000000000000) and \
            (bits & np.uint64(0x000FFFFFFFFFFFFF)) != np.uint64(0):
        return _NAN_KEY
    if bits & _SIGN_BIT:
        return ~bits
    return bits | _SIGN_BIT


@leaf
def _pick_in_order(values, bits, weights, cand, below, target):
    """The first of ``cand`` in value order whose cumulative weight (from ``below``) reaches
    ``target``; the largest when rounding keeps it from being reached."""
    keys = np.empty(cand.shape[0], np.uint64)
    for j in range(cand.shape[0]):
        keys[j] = _order_key(bits[cand[j]])
    order = np.argsort(keys)
    for j in range(order.shape[0]):
        below += weights[cand[order[j]]]
        if below >= target:
            return values[cand[order[j]]]
    return values[cand[order[-1]]]


@leaf
def _radix_histogram(bits, weights, cand, shift):
    """Weight and count of the candidates in each bucket of their key bits ``shift .. shift + 16``."""
    nb = 1 << _RADIX_BITS
    mask = np.uint64(nb - 1)
    hist_w = np.zeros(nb)
    hist_c = np.zeros(nb, np.int64)
    for i in cand:
        b = (_order_key(bits[i]) >> np.uint64(shift)) & mask
        hist_w[b] += weights[i]
        hist_c[b] += 1
    return hist_w, hist_c


@leaf
def _narrow(bits, cand, shift, hist_w, hist_c, below, target):
    """One radix pass over :func:`_radix_histogram`'s buckets: the candidates in the bucket
    where the cumulative weight (from ``below``) reaches ``target`` (the last non-empty bucket
    when rounding keeps it from being reached), and the weight below that bucket."""
    mask = np.uint64(hist_w.shape[0] - 1)
    chosen, last_below = -1, below
    for b in range(hist_w.shape[0]):
        if hist_c[b] == 0:
            continue
        if below + hist_w[b] >= target:
            chosen = b
            break
        chosen, last_below = b, below
        below += hist_w[b]
    else:
        below = last_below
    out = np.empty(hist_c[chosen], np.int64)
    j = 0
    for i in cand:
        if ((_order_key(bits[i]) >> np.uint64(shift)) & mask) == np.uint64(chosen):
            out[j] = i
            j += 1
    return out, below


@leaf
def select_weighted_quantiles(values, weights, fractions, out):
    """Weighted quantiles by radix selection (no sort of all values).

    ``out[k]`` is the smallest value ``v`` among the entries of positive weight whose
    cumulative weight ``W(<= v)`` reaches ``fractions[k] * W`` (``W`` the total positive weight,
    summed in index order); the largest value when rounding keeps it from being reached.
    NaN orders after every number, ``-0.0`` just before ``0.0``. Per fraction: histograms of the
    weights over 16 bits of an order-preserving key at a time, narrowing to the bucket the
    threshold falls in, then a sort of the last few thousand candidates.

    Parameters
    ----------
    values : (n,) float64
    weights : (n,) float64
        Entries of weight <= 0 (or NaN) do not count; at least one must be positive.
    fractions : (k,) float64
        In [0, 1].
    out : (k,) float64
        Output.
    """
    bits = values.view(np.uint64)
    total = 0.0
    count = 0
    for i in range(values.shape[0]):
        if weights[i] > 0.0:
            total += weights[i]
            count += 1
    kept = np.empty(count, np.int64)
    j = 0
    for i in range(values.shape[0]):
        if weights[i] > 0.0:
            kept[j] = i
            j += 1
    top = 64 - _RADIX_BITS  # the first pass's histogram, the same for every fraction
    if count > _SORT_BELOW:
        top_w, top_c = _radix_histogram(bits, weights, kept, top)
    else:
        top_w, top_c = np.zeros(0), np.zeros(0, np.int64)
    for k in range(fractions.shape[0]):
        target = fractions[k] * total
        cand, below, shift = kept, 0.0, 64
        while cand.shape[0] > _SORT_BELOW and shift > 0:
            shift -= _RADIX_BITS
            if shift == top:
                hist_w, hist_c = top_w, top_c
            else:
                hist_w, hist_c = _radix_histogram(bits, weights, cand, shift)
            cand, below = _narrow(bits, cand, shift, hist_w, hist_c, below, target)
        out[k] = _pick_in_order(values, bits, weights, cand, below, target)


@parallel
def grouped_weighted_quantiles(group, values, weights, fractions, out):
    """:func:`select_weighted_quantiles` of each group of entries, the groups in parallel.

    Parameters
    ----------
    group : (n,) int64
        Group of each entry, in ``[0, g)``.
    values, weights : (n,) float64
        As :func:`select_weighted_quantiles` takes them (weights <= 0 or NaN do not count).
    fractions : (k,) float64
        In [0, 1].
    out : (k, g) float64
        Output: NaN for a group without positive weight.
    """
    g = out.shape[1]
    start = np.zeros(g + 1, np.int64)
    for i in range(group.shape[0]):
        if weights[i] > 0.0:
            start[group[i] + 1] += 1
    for j in range(g):
        start[j + 1] += start[j]
    order = np.empty(start[g], np.int64)  # each group's entries in index order
    fill = start[:g].copy()
    for i in range(group.shape[0]):
        if weights[i] > 0.0:
            order[fill[group[i]]] = i
            fill[group[i]] += 1
    for j in prange(g):
        k = start[j + 1] - start[j]
        if k == 0:
            for q in range(fractions.shape[0]):
                out[q, j] = np.nan
            continue
        v = np.empty(k)
        w = np.empty(k)
        for t in range(k):
            v[t] = values[order[start[j] + t]]
            w[t] = weights[order[start[j] + t]]
        res = np.empty(fractions.shape[0])
        select_weighted_quantiles(v, w, fractions, res)
        for q in range(fractions.shape[0]):
            out[q, j] = res[q]
