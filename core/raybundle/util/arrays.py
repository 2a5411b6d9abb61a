"""Array helpers shared by the layers: unique rows, group ids, index ranges, shared edges,
connected components, rows gathered on demand."""
from __future__ import annotations

import numpy as np

from .compiled import helper, kernel, use


def unique_rows(a):
    """``np.unique(a, axis=0, return_index=True, return_inverse=True)[1:]`` for an integer
    array (N, K): returns ``(first, inverse)``, the first row of each distinct value (in the
    lexicographic order of the values) and each row's value id.  By one 1-D sort of a
    mixed-radix key of the columns (the widest made dense ranks first, one by one, while their
    spans are too wide for 63 bits), else by one lexsort; np.unique on rows sorts them as opaque bytes, much slower on
    millions of rows (docs/benchmarks.md, 'Measured choices behind the defaults')."""
    a = np.asarray(a)
    if len(a) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    key = _dense_key([a[:, k] for k in range(a.shape[1])])
    if key is not None:
        return unique_ints(key, own=True)[1:]
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(len(a), bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    inverse = np.empty(len(a), np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new], inverse


def group_ids(columns):
    """Dense ids (N,) of the distinct rows of integer ``columns`` (a list of arrays of one
    shape, or shapes that broadcast to the first's, N its size; the ids flat), as
    :func:`unique_rows` of them side by side gives them, without the (N, K) copy."""
    key = _dense_key(list(columns))
    if key is not None:
        return unique_ints(key, own=True)[2]
    return unique_rows(np.stack([c.ravel() for c in np.broadcast_arrays(*columns)], axis=1))[1]


def _dense_key(cols):
    """:func:`_mixed_radix` of the integer columns ``cols`` (a list as :func:`group_ids` takes
    them, changed here), the widest replaced by its dense ranks first, one by one, while their
    spans are too wide for it; None when even dense ranks do not fit."""
    key = _mixed_radix(cols)
    for k in np.argsort([-(int(c.max()) - int(c.min())) for c in cols]):      # the widest column first
        if key is not None:
            break
        cols[k] = unique_ints(cols[k])[2].reshape(np.shape(cols[k]))
        key = _mixed_radix(cols)
    return key


#: elements a step of :func:`stable_order` adds its indices to at a time
_CHUNK = 1 << 20


def stable_order(key, own=False):
    """``(order, sorted)`` of an integer array ``key`` (N,): ``np.argsort(key, kind="stable")``
    and ``key[order]``.  Where the key's span times N fits in 62 bits, one sort of the values
    ``(key - min) * N + index`` (the order and the values read back from them): a plain sort of
    integers, several times faster than an argsort of them, and compiled as a radix sort
    (:func:`_radix_sort`) from :data:`RADIX_MIN` keys.  With ``own``, an int64 ``key`` is
    worked in place (the caller's to give up)."""
    key = np.asarray(key).reshape(-1)
    n = len(key)
    if n == 0:
        return np.zeros(0, np.int64), key.copy()
    lo, hi = int(key.min()), int(key.max())
    if (hi - lo + 1) * float(n) >= 2.0 ** 62:
        if n < RADIX_MIN or not use() or hi - lo >= 2 ** 62:
            order = np.argsort(key, kind="stable")
            return order, key[order]
        value = key.astype(np.int64, copy=not own)
        value -= lo
        order = np.arange(n)
        _radix_sort(value, np.empty_like(value), (hi - lo).bit_length(), order, np.empty_like(order))
        value += lo
        return order, value.astype(key.dtype, copy=False)
    packed = key.astype(np.int64, copy=not own)      # worked in place: memory of two keys at most
    packed -= lo
    packed *= n
    for start in range(0, n, _CHUNK):
        packed[start:start + _CHUNK] += np.arange(start, min(start + _CHUNK, n))
    if n >= RADIX_MIN and use():
        none = np.zeros(0, np.int64)
        _radix_sort(packed, np.empty_like(packed), ((hi - lo + 1) * n - 1).bit_length(), none, none)
    else:
        packed.sort()
    order = packed % n
    packed //= n                       # the sorted values, in place
    packed += lo
    return order, packed.astype(key.dtype, copy=False)


#: keys from which :func:`stable_order` sorts by :func:`_radix_sort` (below, NumPy's sort)
RADIX_MIN = 1 << 14
#: bits of the digit :func:`_radix_sort` sorts by in one pass
RADIX_BITS = 8


def _radix_sample():
    return np.array([3, 1, 2], np.int64), np.empty(3, np.int64), 2, np.arange(3), np.empty(3, np.int64)


@kernel(_radix_sample)
def _radix_sort(a, buf, bits, idx, ibuf):
    """Sort ``a`` (N,) int64, values in ``[0, 2^bits)``, in place, and ``idx`` (N,) int64 with
    it (or nothing where ``idx`` is empty): least significant digit first,
    :data:`RADIX_BITS` a pass, by counts of every digit from one pass over ``a``, a pass skipped
    where all values share its digit; ``buf`` and ``ibuf`` are their scratch.  Each pass is a
    stable scatter, so the passes together sort stably, in O(N bits / RADIX_BITS) time."""
    n = len(a)
    carry = len(idx) == n
    width = RADIX_BITS
    mask = (1 << width) - 1
    passes = (bits + width - 1) // width
    count = np.zeros((passes, mask + 1), np.int64)
    for i in range(n):
        v = a[i]
        for p in range(passes):
            count[p, (v >> (p * width)) & mask] += 1
    src, dst, isrc, idst = a, buf, idx, ibuf
    moved = False
    for p in range(passes):
        c = count[p]
        if c.max() == n:
            continue
        total = 0
        for d in range(mask + 1):
            here = c[d]
            c[d] = total
            total += here
        shift = p * width
        for i in range(n):
            d = (src[i] >> shift) & mask
            dst[c[d]] = src[i]
            if carry:
                idst[c[d]] = isrc[i]
            c[d] += 1
        src, dst, isrc, idst = dst, src, idst, isrc
        moved = not moved
    if moved:
        a[:] = src
        if carry:
            idx[:] = isrc


def unique_ints(key, own=False, inverse=True):
    """``(values, first, inverse)`` of an integer array ``key`` (N,), as ``np.unique(key,
    return_index=True, return_inverse=True)`` gives them (the distinct values in order, the
    first index of each, each element's value id; None without ``inverse``), by
    :func:`stable_order` (``own`` as there)."""
    order, s = stable_order(key, own)
    new = np.ones(len(s), bool)
    np.not_equal(s[1:], s[:-1], out=new[1:])
    values = s[new]
    if not inverse:
        return values, order[new], None
    ids = np.cumsum(new, out=s if s.dtype == np.int64 else None)      # the sorted values no longer needed
    ids -= 1
    inverse = np.empty(len(s), np.int64)
    inverse[order] = ids
    return values, order[new], inverse


def _mixed_radix(columns):
    """int64 of the first column's shape: the integer ``columns`` (a list of arrays, the others'
    shapes broadcasting to the first's) as the digits of one number, the first most significant
    (so its order is the rows' lexicographic order), or None when their spans do not fit in 62
    bits."""
    lows = [int(np.min(c)) for c in columns]
    spans = [int(np.max(c)) - lo + 1 for c, lo in zip(columns, lows)]
    if np.prod([float(s) for s in spans]) >= 2.0 ** 62:
        return None
    key = np.asarray(columns[0]).astype(np.int64)      # one key made in place: no column copied
    key -= lows[0]
    for c, lo, s in zip(columns[1:], lows[1:], spans[1:]):
        key *= s
        key += c
        key -= lo
    return key


def ranges(start, count):
    """(sum(count),) int64: ``arange(start[i], start[i] + count[i])`` for each i, concatenated
    (``start`` a scalar or (N,), ``count`` (N,) int >= 0), without a loop over i."""
    count = np.asarray(count, np.int64)
    return np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count - start, count)


def shared_edges(corners):
    """``(e1, e2)`` flat edge ids of pairs of triangles meeting along an edge: ``corners`` (N, 3)
    int are the triangles' vertex ids (welded), and edge ``3 t + k`` runs from corner k of
    triangle t to corner k + 1.  Edges at one place (the same two ids, either way round) are
    sorted together, stably, and each consecutive pair of them is returned (three triangles on
    one edge: two pairs)."""
    a = np.asarray(corners).reshape(-1)
    b = np.asarray(corners)[:, [1, 2, 0]].reshape(-1)
    key = np.minimum(a, b, dtype=np.int64)             # one key, made in place
    key *= int(a.max(initial=0)) + 1
    key += np.maximum(a, b)
    del b
    order, key = stable_order(key, own=True)
    same = np.flatnonzero(key[1:] == key[:-1])
    del key
    return order[same], order[same + 1]


def connected_components(n, links):
    """Dense component ids (n,) of n nodes joined by ``links`` (K, 2), numbered in the order of
    each component's smallest node.  Compiled (:mod:`.compiled`): union-find over the links,
    each root the smallest node of its component, in O(n + K) time and an (n,) array of memory.
    The NumPy path: hooking and pointer jumping (Shiloach-Vishkin).  Each round hooks the root of
    every link's larger end onto the smaller root it meets (``minimum.at``: a root's parent
    only ever decreases, so no cycle forms), then jumps pointers until every node points at
    its root."""
    links = np.ascontiguousarray(links, np.int64).reshape(-1, 2)
    if use():
        out = np.empty(n, np.int64)
        _components(links, out)
        return out
    parent = np.arange(n)
    a, b = links.T
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


def _components_sample():
    return np.array([[0, 1]], np.int64), np.empty(3, np.int64)


@helper
def _root(parent, x):
    """The root of node ``x``, halving the path to it."""
    while parent[x] != x:
        parent[x] = parent[parent[x]]
        x = parent[x]
    return x


@kernel(_components_sample)
def _components(links, out):
    """``out`` (n,) = :func:`connected_components` of ``links`` (K, 2): each link joins the two
    roots, the larger under the smaller (so a root is its component's smallest node); then the
    nodes in order, each root taking the next id and every other node its root's."""
    n = len(out)
    parent = np.arange(n)
    for k in range(links.shape[0]):
        ra, rb = _root(parent, links[k, 0]), _root(parent, links[k, 1])
        if ra < rb:
            parent[rb] = ra
        elif rb < ra:
            parent[ra] = rb
    label = 0
    for x in range(n):
        r = _root(parent, x)
        if r == x:
            out[x] = label
            label += 1
        else:
            out[x] = out[r]


class GatheredRows:
    """``values[index]`` (an array of ``values``' rows, ``index`` of any shape) without holding it:
    indexing gathers only the rows asked for, ``x[key] == values[index][key]`` (the key's first
    ``index.ndim`` parts index ``index``, the rest the rows); a whole-array step (``np.asarray``,
    a ufunc, :meth:`mean`, :meth:`min`, :meth:`max`, :meth:`reshape`) gathers it all for that
    step only.  With ``flip_from`` (a 1-D ``index``), the rows at and past that position come
    out negated (the normals of triangles' back sides).  A scene of millions of triangles
    holding its corners and side normals gathered would hold several times its vertices."""

    def __init__(self, values, index, flip_from=None):
        self.values, self.index, self.flip_from = values, index, flip_from

    @property
    def shape(self):
        return self.index.shape + self.values.shape[1:]

    @property
    def ndim(self):
        return len(self.shape)

    @property
    def dtype(self):
        return self.values.dtype

    def __len__(self):
        return len(self.index)

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        if any(k is Ellipsis or k is None for k in key):
            return np.asarray(self)[key]
        at = key[:self.index.ndim]
        where = self.index[at]
        rows = self.values[(where,) + key[self.index.ndim:]]
        return self._flipped(np.array(rows) if np.ndim(where) == 0 else rows, at)      # a row: a view

    def _flipped(self, rows, at):
        """``rows`` (fresh) gathered at ``at`` of ``index``, those at and past ``flip_from`` negated."""
        if self.flip_from is None:
            return rows
        k = at[0]
        k = np.arange(*k.indices(len(self.index))) if isinstance(k, slice) else np.asarray(k)
        if k.dtype == bool:
            k = np.nonzero(k)[0]
        elif k.size and k.min() < 0:
            k = np.where(k < 0, k + len(self.index), k)
        back = k >= self.flip_from
        if back.any():
            rows[back] *= -1.0
        return rows

    def __array__(self, dtype=None, copy=None):
        out = self._flipped(self.values[self.index], (slice(None),))
        return out if dtype is None else out.astype(dtype)

    def _whole(name):                   # an operator on the whole array gathers it for that step
        return lambda self, *args: getattr(np.asarray(self), name)(*args)

    __add__, __radd__, __sub__, __rsub__ = _whole("__add__"), _whole("__radd__"), _whole("__sub__"), _whole("__rsub__")
    __mul__, __rmul__, __truediv__, __rtruediv__ = (_whole("__mul__"), _whole("__rmul__"), _whole("__truediv__"),
                                                    _whole("__rtruediv__"))
    __matmul__, __rmatmul__, __neg__ = _whole("__matmul__"), _whole("__rmatmul__"), _whole("__neg__")
    __gt__, __ge__, __lt__, __le__ = _whole("__gt__"), _whole("__ge__"), _whole("__lt__"), _whole("__le__")
    del _whole

    def mean(self, *args, **kw):
        return np.asarray(self).mean(*args, **kw)

    def min(self, *args, **kw):
        return np.asarray(self).min(*args, **kw)

    def max(self, *args, **kw):
        return np.asarray(self).max(*args, **kw)

    def reshape(self, *shape):
        return np.asarray(self).reshape(*shape)
