"""A stable least-significant-digit radix sort of int64 keys, compiled: linear in the keys, for the kernels that
order triangles (the pads' hierarchy) and facet members (segmentation)."""

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
