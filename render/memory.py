"""Keep the memory a frame frees for the next frame.

A frame is made from a few dozen full-size float temporaries (7.7 MB each for three channels at
800x800).  glibc's allocator hands blocks over its mmap threshold (128 KiB at first, raised as
blocks are freed, up to 32 MiB) straight to the kernel and returns them on free, and gives the
heap's free top back once it exceeds its trim threshold.  Either way the next frame's arrays fault
every page in again, and zeroing pages costs more than much of the arithmetic done in them.
Measured on the realism suite's real tier (800x800, every realism feature on), 10 frames: 136k
minor page faults and 160-169 ms a frame; with freed memory kept, 39k and 149-154 ms, for a
peak resident size 1.5 % larger (669 -> 678 MB).  Plain frames change little (85k faults, 102 ->
99 ms): they allocate fewer and more uniform blocks, which the dynamic threshold already keeps.

:func:`keep_freed_memory` fixes both thresholds at 1 GiB for the whole process (glibc's
``mallopt``): freed blocks stay in the heap and are reused.  It changes no computed value.
Elsewhere (another C library, another system) it does nothing and says so.
"""
from __future__ import annotations

import ctypes
import ctypes.util

M_TRIM_THRESHOLD = -1  # glibc's <malloc.h>
M_MMAP_THRESHOLD = -3
KEEP_BYTES = 1 << 30

_kept: bool | None = None


def keep_freed_memory() -> bool:
    """Ask the C allocator to keep freed memory for reuse (once per process); whether it agreed."""
    global _kept
    if _kept is None:
        _kept = False
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            mallopt = libc.mallopt
        except (OSError, AttributeError, TypeError):  # not glibc
            return False
        mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
        _kept = bool(mallopt(M_MMAP_THRESHOLD, KEEP_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD, KEEP_BYTES))
    return _kept
