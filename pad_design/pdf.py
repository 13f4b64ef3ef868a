"""Printable pad: one true-scale page, and the same pad tiled over A4 sheets for home printers.

Uses matplotlib's PDF backend (already a dependency): the page size is the figure size, set in
inches from metres, and the texture is embedded unresampled (``interpolation='none'``).
"""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg", force=False)
from matplotlib.backends.backend_pdf import PdfPages  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

INCH = 0.0254
A4_M = (0.210, 0.297)
TILE_MARGIN_M = 0.010   # unprinted margin kept on every side of an A4 sheet
TILE_OVERLAP_M = 0.015  # each tile repeats this much of its neighbour, for gluing


def _page(width_m: float, height_m: float) -> Figure:
    return Figure(figsize=(width_m / INCH, height_m / INCH), dpi=72)


def tile_grid(side_m: float, sheet_m=A4_M, margin_m: float = TILE_MARGIN_M, overlap_m: float = TILE_OVERLAP_M):
    """Tiles ``(x0, y0, w, h)`` in metres from the pad's top-left corner, and the sheet orientation."""
    best = None
    for sw, sh in (sheet_m, sheet_m[::-1]):
        pw, ph = sw - 2 * margin_m, sh - 2 * margin_m
        nx = max(1, math.ceil((side_m - overlap_m) / (pw - overlap_m)))
        ny = max(1, math.ceil((side_m - overlap_m) / (ph - overlap_m)))
        if best is None or nx * ny < best[0]:
            best = (nx * ny, nx, ny, pw, ph, (sw, sh))
    _, nx, ny, pw, ph, sheet = best
    tiles = []
    for r in range(ny):
        for c in range(nx):
            x0 = min(c * (pw - overlap_m), max(side_m - pw, 0.0))
            y0 = min(r * (ph - overlap_m), max(side_m - ph, 0.0))
            tiles.append((r, c, x0, y0, min(pw, side_m), min(ph, side_m)))
    return tiles, sheet


def write_pdfs(pad, out_dir) -> dict:
    out = Path(out_dir)
    side = pad.side_m
    img = pad.texture_rgb
    n = img.shape[0]
    ppm = n / side
    # one page at true scale
    fig = _page(side, side)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.imshow(img, interpolation="none", extent=(0, side, side, 0))
    ax.set_axis_off()
    single = out / "pad.pdf"
    fig.savefig(single, dpi=max(72, int(round(ppm * INCH))))
    # tiled A4 sheets with overlap and alignment marks
    tiles, (sw, sh) = tile_grid(side)
    tiled = out / "pad_a4_tiles.pdf"
    with PdfPages(tiled) as pdf:
        for r, c, x0, y0, w, h in tiles:
            fig = _page(sw, sh)
            ax = fig.add_axes((TILE_MARGIN_M / sw, 1 - (TILE_MARGIN_M + h) / sh, w / sw, h / sh))
            i0, i1 = int(round(y0 * ppm)), int(round((y0 + h) * ppm))
            j0, j1 = int(round(x0 * ppm)), int(round((x0 + w) * ppm))
            ax.imshow(img[i0:i1, j0:j1], interpolation="none",
                      extent=(j0 / ppm, j1 / ppm, i1 / ppm, i0 / ppm))
            ax.set_xlim(x0, x0 + w)
            ax.set_ylim(y0 + h, y0)
            ax.set_axis_off()
            # alignment crosses every 5 cm on the overlap lines, where the next tile repeats them
            for xm in (x0 + TILE_OVERLAP_M / 2, x0 + w - TILE_OVERLAP_M / 2):
                for ym in (y0 + TILE_OVERLAP_M / 2, y0 + h - TILE_OVERLAP_M / 2):
                    ax.plot([xm - 0.004, xm + 0.004], [ym, ym], color="cyan", lw=0.4)
                    ax.plot([xm, xm], [ym - 0.004, ym + 0.004], color="cyan", lw=0.4)
            fig.text(0.5, 0.004 / sh, f"hvloc pad {side * 1000:.0f} mm - row {r + 1}, column {c + 1} - "
                     f"overlap {TILE_OVERLAP_M * 1000:.0f} mm - print at 100% (no scaling)",
                     ha="center", va="bottom", fontsize=6)
            pdf.savefig(fig, dpi=max(72, int(round(ppm * INCH))))
    return {"pad.pdf": single, "pad_a4_tiles.pdf": tiled}
