"""Array helpers shared by the layers: unique rows, group ids, connected components."""
from __future__ import annotations

import numpy as np


def unique_rows(a):
    """``np.unique(a, axis=0, return_index=True, return_inverse=True)[1:]`` for an integer
    array (N, K), by one lexsort (np.unique sorts the rows as opaque bytes, much slower on
    millions of rows: README, 'Measured choices behind the defaults').  Returns
    ``(first, inverse)``: the first row of each distinct value (in the lexicographic order of
    the values) and each row's value id."""
    a = np.asarray(a)
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(len(a), bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    inverse = np.empty(len(a), np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def group_ids(columns):
    """Dense ids (N,) of the distinct rows of integer ``columns`` (a list of (N,) arrays):
    one 1-D sort of a mixed-radix key when it fits in 63 bits, else :func:`unique_rows`."""
    cols = [np.asarray(c, np.int64) - np.min(c) for c in columns]
    spans = [int(c.max()) + 1 for c in cols]
    if np.prod([float(s) for s in spans]) < 2.0 ** 62:
        key = np.zeros(len(cols[0]), np.int64)
        for c, s in zip(cols, spans):
            key = key * s + c
        return np.unique(key, return_inverse=True)[1].reshape(-1)
    return unique_rows(np.stack(cols, axis=1))[1]


def connected_components(n, links):
    """Dense component ids (n,) of n nodes joined by ``links`` (K, 2), numbered in the order of
    each component's smallest node: hooking and pointer jumping (Shiloach-Vishkin).  Each round
    hooks the root of every link's larger end onto the smaller root it meets (``minimum.at``:
    a root's parent only ever decreases, so no cycle forms), then jumps pointers until every
    node points at its root."""
    parent = np.arange(n)
    a, b = np.asarray(links, np.int64).reshape(-1, 2).T
    while len(a):
        pa, pb = parent[a], parent[b]
        apart = pa != pb
        a, b, pa, pb = a[apart], b[apart], pa[apart], pb[apart]
        np.minimum.at(parent, np.maximum(pa, pb), np.minimum(pa, pb))
        while True:
            jumped = parent[parent]
            if np.array_equal(jumped, parent):
                break
            parent = jumped
    return np.unique(parent, return_inverse=True)[1].reshape(-1)
