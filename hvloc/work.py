"""The localizer's image work, shareable between localizers that see the same frame.

The hierarchical localizer's decisions (phase, method order, gates, keyframes) are cheap; its cost
is image work: colour segmentation, contour nesting, corner refinement, Harris corners, Lucas-Kanade
tracking.  Each of those is a pure function of the frame and of a few inputs that the localizer's
state decides (a region of interest, the keyframe, the tracks to follow).  :class:`ImageWork` runs
them, and when several localizers process the same frame (a switch-height sweep, a suite's
ablations) it remembers each result under a key that names every such input, so a second localizer
asking the same question gets the same answer without the work, and a different question is
computed afresh.  So a sweep is exactly as many live runs, at the cost of the work they do not share.

A live localizer has its own :class:`ImageWork` with no frame set: every call simply runs.
"""
from __future__ import annotations

import copy


class ImageWork:
    """``work(key, fn, *args)``: ``fn(*args)``, remembered under ``key()`` for the current frame.

    ``key`` is a function returning the key, called only when a frame is set: a live localizer (no
    frame) pays nothing for keys it would not use.  ``begin(frame)`` starts a frame (and forgets the
    previous one's results: no key of one frame can ask for another's work, since each names the
    frame tags it depends on).  Results are returned as deep copies, so no caller can change what
    another is given; ``copy_result=False`` for read-only arrays too large to copy (the image)."""

    def __init__(self):
        self.frame = None
        self._memo: dict = {}
        self.calls = 0
        self.hits = 0

    def begin(self, frame) -> None:
        self.frame = frame
        self._memo.clear()

    def __call__(self, key, fn, *args, copy_result: bool = True, **kwargs):
        if self.frame is None:
            return fn(*args, **kwargs)
        key = key()
        self.calls += 1
        try:
            value = self._memo[key]
            self.hits += 1
        except KeyError:
            value = self._memo[key] = fn(*args, **kwargs)
        return copy.deepcopy(value) if copy_result else value


def array_key(a) -> tuple | None:
    """A hashable, exact key for an array (shape and bytes), ``None`` for ``None``."""
    if a is None:
        return None
    import numpy as np

    a = np.ascontiguousarray(a)
    return (a.shape, str(a.dtype), a.tobytes())
