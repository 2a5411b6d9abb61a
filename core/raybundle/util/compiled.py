"""Compiled kernels: plain Python loops over NumPy arrays, compiled by Numba.

A kernel is a function of arrays and scalars written as loops (:func:`kernel` marks it). Numba
compiles it (``njit``, ``nogil``) the first time it runs in a process, or loads it from the
on-disk cache (:func:`cache_folder`), so that a pass does per element in registers what NumPy
would do in whole-array steps that each read and write memory. :func:`compile_all` compiles
every kernel of the imported modules at once (the set-up's "compiling the kernels" phase) and
says how long it took.

Numba is a dependency; where it cannot be imported (a platform without its wheels, a NumPy it
does not support) :data:`ENABLED` is False, callers take their NumPy path, the same arithmetic,
and one warning says why.  ``RAYBUNDLE_KERNELS=numpy`` takes the NumPy path on purpose (the tests
compare the two).

The cache is never written beside the code (an installed extension's folder may be read-only
and is replaced on update): :data:`CACHE_FOLDER` when set (the add-on sets its user folder),
else ``$RAYBUNDLE_KERNEL_CACHE``, else the user's cache folder (``$XDG_CACHE_HOME`` or
``~/.cache`` on Linux, ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%`` on Windows) under
``raybundle/kernels``.
"""
from __future__ import annotations

import os
import sys
import time
import warnings

#: the folder compiled kernels are cached in (None: :func:`cache_folder`'s default)
CACHE_FOLDER = None
#: kernels marked by :func:`kernel`, with their sample arguments, in the order they were defined
_KERNELS: list = []
#: whether :func:`use` has said that the NumPy path runs
_warned = False

try:
    if os.environ.get("RAYBUNDLE_KERNELS", "").lower() == "numpy":
        raise ImportError("RAYBUNDLE_KERNELS=numpy")
    import numba
    ENABLED, REASON = True, ""
except Exception as e:                          # ImportError, or a NumPy version Numba refuses
    numba, ENABLED, REASON = None, False, f"{type(e).__name__}: {e}".splitlines()[0]


def cache_folder():
    """The folder compiled kernels are cached in (module docstring)."""
    if CACHE_FOLDER:
        return CACHE_FOLDER
    if os.environ.get("RAYBUNDLE_KERNEL_CACHE"):
        return os.environ["RAYBUNDLE_KERNEL_CACHE"]
    home = os.path.expanduser("~")
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or os.path.join(home, "AppData", "Local")
    elif sys.platform == "darwin":
        base = os.path.join(home, "Library", "Caches")
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(home, ".cache")
    return os.path.join(base, "raybundle", "kernels")


class Kernel:
    """A function compiled on its first call (or by :func:`compile_all`); where Numba is not
    enabled, never called (its callers take their NumPy path: :func:`use`)."""

    def __init__(self, fn, samples):
        self.fn, self.samples, self._compiled = fn, samples, None
        self.__doc__, self.__name__ = fn.__doc__, fn.__name__

    def compiled(self):
        if self._compiled is None:
            numba.config.CACHE_DIR = cache_folder()     # read when the dispatcher's cache is made
            self._compiled = numba.njit(cache=True, nogil=True)(self.fn)
        return self._compiled

    def __call__(self, *args):
        return self.compiled()(*args)


def kernel(*samples):
    """Mark a function as a kernel; each ``sample()`` gives arguments it compiles for (small
    arrays of the types and dimensions its callers pass: one sample per set of types)."""
    def mark(fn):
        k = Kernel(fn, samples)
        _KERNELS.append(k)
        return k
    return mark


def helper(fn):
    """Mark a function that kernels call: compiled into each kernel that calls it (so it is
    cached with them, never on its own); the plain function where Numba is not enabled."""
    return numba.njit(nogil=True)(fn) if ENABLED else fn


def use():
    """Whether callers take the kernels (Numba enabled), else their NumPy path: on the first
    NumPy-path call a warning says why."""
    global _warned
    if not ENABLED and not _warned:
        _warned = True
        if REASON != "ImportError: RAYBUNDLE_KERNELS=numpy":
            warnings.warn(f"raybundle: Numba is not available ({REASON}): the NumPy path is used (slower)",
                          RuntimeWarning, stacklevel=3)
    return ENABLED


def compile_all():
    """Compile (or load from the cache) every kernel not yet compiled in this process; returns
    the seconds it took (0 without Numba)."""
    if not ENABLED:
        return 0.0
    t0 = time.perf_counter()
    for k in _uncompiled():
        for sample in k.samples:
            k(*sample())
    return time.perf_counter() - t0


def pending():
    """Whether :func:`compile_all` has work left in this process."""
    return ENABLED and bool(_uncompiled())


def _uncompiled():
    return [k for k in _KERNELS if k._compiled is None or len(k._compiled.signatures) < len(k.samples)]
