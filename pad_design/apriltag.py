"""AprilTag 3's ``tagCustom48h12`` family, as data: the layout of its cells and its first codes.

This family is the one that nests: a 10 x 10 cell tag whose detected square (``width_at_border``,
6 cells) is a white ring inside a black one ("reversed border"), with data bits on the outermost
ring and on a ring inside the white one, and its centre 2 x 2 cells free, so that a tag one fifth
the size fits there: a "recursive" landing pad, readable from high up (the large tag) down to the
last decimetres (the small one).  Facts from the AprilTag library's family definition (bit ``i``
of a code, most significant first, is the cell ``(bit_x[i], bit_y[i])`` counted from the corner of
the detected square; a set bit is white).  Detected with ``pupil_apriltags`` (the AprilTag library).
"""
from __future__ import annotations

import numpy as np

FAMILY = "tagCustom48h12"
TOTAL_CELLS = 10          # the whole tag, data ring included
BORDER_CELLS = 6          # the square the detector finds (its corners are the tag's corners)
CENTRE_CELLS = 2          # free in the middle: room for a nested tag of TOTAL_CELLS smaller cells
CODES = (0xd6c8ae76dff0, 0xd6c8e905e5b5, 0xd6c92394eb7a, 0xd6c95e23f13f,
         0xd6c998b2f704, 0xd6c9d341fcc9, 0xd6ca0dd1028e, 0xd6ca48600853)
BIT_X = (-2, -1, 0, 1, 2, 3, 4, 5, 6, 1, 2, 3, 7, 7, 7, 7, 7, 7, 7, 7, 7, 4, 4, 4,
         7, 6, 5, 4, 3, 2, 1, 0, -1, 4, 3, 2, -2, -2, -2, -2, -2, -2, -2, -2, -2, 1, 1, 1)
BIT_Y = (-2, -2, -2, -2, -2, -2, -2, -2, -2, 1, 1, 1, -2, -1, 0, 1, 2, 3, 4, 5, 6, 1, 2, 3,
         7, 7, 7, 7, 7, 7, 7, 7, 7, 4, 4, 4, 7, 6, 5, 4, 3, 2, 1, 0, -1, 4, 3, 2)
# pupil_apriltags' corner order (counter-clockwise in the image of an upright tag: bottom-left,
# bottom-right, top-right, top-left) as indices into the pad's TL, TR, BR, BL
DETECTOR_TO_PAD_CORNERS = (3, 2, 1, 0)


def tag_cells(tag_id: int) -> np.ndarray:
    """``(10, 10)`` bool: the tag's white cells, row 0 at the top as printed."""
    if not 0 <= tag_id < len(CODES):
        raise ValueError(f"tag id {tag_id}: this build carries ids 0-{len(CODES) - 1} of {FAMILY}")
    cells = np.zeros((TOTAL_CELLS, TOTAL_CELLS), bool)
    a, b = (TOTAL_CELLS - BORDER_CELLS) // 2, (TOTAL_CELLS + BORDER_CELLS) // 2 - 1  # the white ring
    cells[a, a:b + 1] = cells[b, a:b + 1] = cells[a:b + 1, a] = cells[a:b + 1, b] = True
    code = CODES[tag_id]
    n = len(BIT_X)
    for i, (x, y) in enumerate(zip(BIT_X, BIT_Y)):
        if code >> (n - 1 - i) & 1:
            cells[y + a, x + a] = True
    return cells
