"""Freed memory given back to the system between a run's steps.

A step's temporary arrays, once freed, stay in the C heap as free space: glibc's malloc keeps
arrays under its mapping threshold (adjusted up to 32 MB as arrays are freed) in its heaps and
gives the pages back only from a heap's top, while larger arrays are mapped apart and never
reuse that space.  After a step whose temporaries outweigh what follows (the first image pass,
which samples every pixel's penumbra), that free space would sit under every later peak.
:func:`release_freed` asks glibc to return it (``malloc_trim``); elsewhere it does nothing.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import sys


def _trim():
    """glibc's ``malloc_trim``, or None where the C library has none (macOS, Windows, musl)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


_MALLOC_TRIM = _trim()


def release_freed():
    """Return the C heap's free pages to the system; True where that could be asked."""
    if _MALLOC_TRIM is None:
        return False
    _MALLOC_TRIM(0)
    return True
