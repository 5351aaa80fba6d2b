"""Stable least-significant-digit radix sorts of int64 keys, compiled: linear in the keys, for the kernels that
order triangles (the pads' hierarchy, segmentation's seeds) and facet members (segmentation)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def radix_sort(src, dst, shift, stop, digit):
    """`src` (m,) sorted stably by its bits [shift, stop), `digit` bits per pass, `dst` (m,) the scratch: returns
    whichever of the two holds the result (both are overwritten)."""
    size = 1 << digit
    count = np.empty(size + 1, dtype=np.int64)
    m = src.shape[0]
    while shift < stop:
        count[:] = 0
        for i in range(m):
            count[((src[i] >> shift) & (size - 1)) + 1] += 1
        for d in range(size):
            count[d + 1] += count[d]
        for i in range(m):
            d = (src[i] >> shift) & (size - 1)
            dst[count[d]] = src[i]
            count[d] += 1
        src, dst = dst, src
        shift += digit
    return src


@njit(cache=True)
def descending_order(keys):
    """The indices (n,) of the non-negative int64 `keys` from the largest, ties by index: numpy's stable argsort of
    their negatives (segmentation's seed order, by area: a non-negative float's bits order as its value), in
    16-bit digits, passes whose digit is the same for every key skipped. Linear in n."""
    n = keys.shape[0]
    key, idx = np.empty(n, dtype=np.int64), np.arange(n)
    key2, idx2 = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
    top = 0
    for i in range(n):
        key[i] = 0x7FFFFFFFFFFFFFFF - keys[i]  # ascending in this: descending in the key
        top |= key[i] ^ key[0]
    count = np.empty(65537, dtype=np.int64)
    for shift in range(0, 64, 16):
        if (top >> shift) & 0xFFFF == 0:
            continue  # every key has the same digit here
        count[:] = 0
        for i in range(n):
            count[((key[i] >> shift) & 0xFFFF) + 1] += 1
        for d in range(65536):
            count[d + 1] += count[d]
        for i in range(n):
            d = (key[i] >> shift) & 0xFFFF
            key2[count[d]], idx2[count[d]] = key[i], idx[i]
            count[d] += 1
        key, key2, idx, idx2 = key2, key, idx2, idx
    return idx
