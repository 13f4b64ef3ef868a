"""The pad designer: exact geometry, finder markers, Harris coverage, printable output, bad specs."""
import json
import math
import re
import subprocess
import sys

import cv2
import numpy as np
import pytest

from hvloc import markers as mk
from hvloc.geometry import Camera
from pad_design import PadSpec, make_pad, write_pad
from pad_design.pdf import A4_M, tile_grid
from render.planar import nadir_cam2pad, warp_pad_view
from tests.conftest import assert_input_error, run_cli


def listed_corners(geometry):
    pts = [geometry.outer_corners, geometry.field_corners, geometry.cue.corners]
    pts += [sq.corners for m in geometry.markers for sq in m.squares]
    return np.concatenate(pts)[:, :2]


def test_every_listed_corner_is_where_texture_edges_meet(pad):
    assert abs(pad.ppm - 2000) < 1e-9
    margin = 20
    gray = cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2GRAY)
    gray = cv2.copyMakeBorder(gray, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255)
    pts = listed_corners(pad.geometry)
    assert len(pts) == 4 + 4 + 4 + 3 * 3 * 4
    truth = pad.to_texture_px(np.column_stack([pts, np.zeros(len(pts))])) + margin
    start = (truth + np.array([0.7, -0.6])).astype(np.float32).reshape(-1, 1, 2)
    found = cv2.cornerSubPix(gray.astype(np.float32), start.copy(), (5, 5), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4))[:, 0, :]
    err = np.linalg.norm(found - truth, axis=1)
    assert err.max() <= 0.25, f"worst corner off by {err.max():.3f} px at {pts[err.argmax()]}"


def _rotate(img, angle_deg):
    h, w = img.shape[:2]
    d = int(math.ceil(math.hypot(h, w))) + 20
    M = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), angle_deg, 1.0)
    M[:, 2] += [(d - w) / 2, (d - h) / 2]
    out = cv2.warpAffine(img, M, (d, d), flags=cv2.INTER_LINEAR, borderValue=200)
    return out, M


def test_exactly_three_finder_nests_named_right_at_36_yaws(pad):
    small = cv2.resize(cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2GRAY), None, fx=0.5, fy=0.5,
                       interpolation=cv2.INTER_AREA)
    centres = {m.name: pad.to_texture_px(np.array([m.center]))[0] * 0.5 + 0.25 - 0.5
               for m in pad.markers("corner")}
    # at full resolution, the texture holds exactly three nests
    full = mk.find_finder_nests(mk.binarize_dark(cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2GRAY)))
    assert len(full) == 3
    for k in range(36):
        angle = 10.0 * k
        img, M = _rotate(small, angle)
        nests = mk.find_finder_nests(mk.binarize_dark(img))
        assert len(nests) == 3, f"yaw {angle}: {len(nests)} nests"
        triples = mk.find_marker_triples(nests)
        assert len(triples) == 1
        for name, nest in triples[0].by_name.items():
            expect = M @ np.append(centres[name], 1.0)
            assert np.linalg.norm(nest.center_px - expect) < 2.0, f"yaw {angle}: {name} misnamed"


def test_harris_coverage_at_touchdown_height(pad):
    """A 60-degree camera 0.15 m above any point of the pad sees >= 40 well-spread Harris corners."""
    cam = Camera.from_hfov(480, 480, math.radians(60))
    rng = np.random.default_rng(2024)
    half = pad.side_m / 2
    worst = (10**9, None)
    worst_spread = (1.0, None)
    for _ in range(200):
        x, y = rng.uniform(-half, half, 2)
        img = warp_pad_view(pad, cam, nadir_cam2pad(x, y, 0.15, rng.uniform(0, 2 * math.pi)),
                            background=(128, 128, 128))
        gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
        c = cv2.goodFeaturesToTrack(gray, 500, 0.01, 10, useHarrisDetector=True, k=0.04)
        n = 0 if c is None else len(c)
        spread = 0.0 if n < 2 else float(min(c[:, 0, 0].std(), c[:, 0, 1].std()) / 480)
        worst = min(worst, (n, (x, y)))
        worst_spread = min(worst_spread, (spread, (x, y)))
    assert worst[0] >= 40, f"only {worst[0]} Harris corners above pad point {worst[1]}"
    # well spread: the corners' standard deviation is >= 10% of the image along both axes
    assert worst_spread[0] >= 0.10, f"corners bunched (std {worst_spread[0]:.3f}) above {worst_spread[1]}"


def test_pad_json_document(pad, tmp_path):
    files = write_pad(pad, tmp_path, pdf=False)
    doc = json.loads(files["pad.json"].read_text())
    assert doc["version"] == 1 and doc["side_m"] == 0.85
    assert [m["name"] for m in doc["markers"]] == ["Top", "Right", "Bottom"]
    tl, tr, br, bl = np.asarray(doc["outer_corners"])
    assert tl[0] < 0 < tl[1] and tr[0] > 0 and tr[1] > 0 and br[0] > 0 > br[1] and bl[0] < 0 and bl[1] < 0
    top = next(m for m in doc["markers"] if m["name"] == "Top")
    assert top["center"][0] < 0 < top["center"][1]  # Top is the right-angle corner, top-left as printed
    lo, hi = doc["border"]["segmentation_hsv"]["lo"], doc["border"]["segmentation_hsv"]["hi"]
    # the border colour is inside its own segmentation range
    hsv = cv2.cvtColor(np.uint8([[doc["border"]["color_rgb"]]]), cv2.COLOR_RGB2HSV)[0, 0]
    assert lo[0] <= hsv[0] <= hi[0] and hsv[1] >= lo[1] and hsv[2] >= lo[2]
    assert doc["cue"]["corner"] == "bottom_right" and len(doc["texture"]["sha256"]) == 64
    # re-loading gives the same pad
    from pad_design import Pad

    again = Pad.load(files["pad.json"])
    assert np.array_equal(again.texture_rgb, pad.texture_rgb)


def _media_boxes(path):
    data = path.read_bytes()
    return [tuple(float(v) for v in m) for m in
            re.findall(rb"/MediaBox\s*\[\s*([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s*\]", data)]


def test_pdf_true_scale_and_a4_tiles(tmp_path):
    pad = make_pad(ppm=400)
    files = write_pad(pad, tmp_path)
    (box,) = _media_boxes(files["pad.pdf"])
    to_mm = 25.4 / 72
    assert abs((box[2] - box[0]) * to_mm - 850) < 0.1 and abs((box[3] - box[1]) * to_mm - 850) < 0.1
    boxes = _media_boxes(files["pad_a4_tiles.pdf"])
    tiles, sheet = tile_grid(pad.side_m)
    assert len(boxes) == len(tiles) >= 4
    a4 = sorted(x * 1000 for x in A4_M)
    for b in boxes:
        assert sorted([(b[2] - b[0]) * to_mm, (b[3] - b[1]) * to_mm]) == pytest.approx(a4, abs=0.1)
    # the tiles cover the whole pad, and each fits its sheet inside the margins
    cover = np.zeros((850, 850), bool)
    for _, _, x0, y0, w, h in tiles:
        assert w <= sheet[0] - 0.02 + 1e-9 and h <= sheet[1] - 0.02 + 1e-9
        cover[int(round(y0 * 1000)):int(round((y0 + h) * 1000)), int(round(x0 * 1000)):int(round((x0 + w) * 1000))] = True
    assert cover.all()


def test_nested_variant_has_two_marker_sets():
    pad = make_pad({"variant": "nested"}, ppm=1500)
    gray = cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2GRAY)
    nests = mk.find_finder_nests(mk.binarize_dark(gray))
    assert len(nests) == 6
    triples = mk.find_marker_triples(nests)
    assert len(triples) == 2
    ratios = sorted(t.spacing_ratio for t in triples)
    m = pad.geometry.markers
    expect = sorted([m[0].size_m / (2 * abs(m[0].center[0])), m[3].size_m / (2 * abs(m[3].center[0]))])
    np.testing.assert_allclose(ratios, expect, rtol=0.15)


def test_aruco_variant_detected_by_opencv_at_listed_corners():
    pad = make_pad({"variant": "aruco"}, ppm=1000)
    gray = cv2.cvtColor(pad.texture_rgb, cv2.COLOR_RGB2GRAY)
    d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50)
    det = cv2.aruco.ArucoDetector(d, cv2.aruco.DetectorParameters())
    corners, ids, _ = det.detectMarkers(gray)
    assert ids is not None and sorted(ids.ravel().tolist()) == [0, 1, 2]
    for c, i in zip(corners, ids.ravel()):
        m = next(m for m in pad.geometry.markers if m.aruco_id == i)
        truth = pad.to_texture_px(m.outer_corners)
        # OpenCV reports corners on the outer edge of the black border, +-1 px
        assert np.abs(c[0] - truth).max() < 1.5


BAD_SPECS = [
    ("side_m: -0.5\n", "side_m"),
    ("sidem: 1.0\n", "sidem: unknown key"),
    ("marker_size_m: 0.4\n", "marker_size_m"),
    ("border_color: '#00ff00'\n", "border_color"),
    ("cue_color: not-a-colour\n", "cue_color"),
    ("variant: nested\nnested_marker_size_m: 0.3\n", "nested_marker_size_m"),
    ("- a list\n", "mapping"),
]


@pytest.mark.parametrize("text,names", BAD_SPECS)
def test_bad_spec_exits_2_naming_the_field_and_writes_nothing(tmp_path, text, names):
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    out = tmp_path / "out"
    assert_input_error(run_cli("pad", "make", "--spec", spec, "--out", out), names)
    assert not out.exists()


def test_spec_defaults_are_the_papers_pad():
    s = PadSpec()
    assert s.side_m == 0.85 and s.variant == "paper"


def _artwork(path, size=(600, 600)):
    """A helipad-like picture: a dark frame, a red ring, an H and scattered dots."""
    rng = np.random.default_rng(0)
    img = np.full((size[1], size[0], 3), 235, np.uint8)
    s = min(size) / 900
    cv2.rectangle(img, (0, 0), (size[0] - 1, size[1] - 1), (40, 120, 20), int(60 * s))
    cv2.circle(img, (size[0] // 2, size[1] // 2), int(250 * s), (20, 20, 200), int(40 * s))
    cv2.putText(img, "H", (int(330 * s), int(600 * s)), cv2.FONT_HERSHEY_SIMPLEX, 12 * s, (30, 30, 30), int(60 * s))
    for _ in range(300):
        x, y = rng.integers(int(70 * s), int(830 * s), 2)
        cv2.circle(img, (int(x), int(y)), int(rng.integers(3, 12) * s) + 1, (int(rng.integers(0, 120)),) * 3, -1)
    cv2.imwrite(str(path), img)
    return path


def test_a_pad_from_your_own_artwork_is_made_validated_and_printed(tmp_path):
    """variant artwork: the user's image over the whole pad and the points it names; pad.json keeps
    them (no border, cue or markers of hvloc's), pad.png is the image at the pad's resolution, and
    the true-scale and A4 PDFs are written as for hvloc's own pads."""
    from pad_design.pad import Pad

    art = _artwork(tmp_path / "art.png")
    spec = {"variant": "artwork", "side_m": 0.8, "artwork_image": str(art),
            "artwork_points": {"ring_top": [0.0, 0.222], "corner_tl": [-0.4, 0.4]}}
    pad = make_pad(spec, ppm=1000)
    assert pad.texture_rgb.shape == (800, 800, 3) and pad.geometry.variant == "artwork"
    assert pad.geometry.border is None and pad.geometry.cue is None and pad.geometry.markers == ()
    np.testing.assert_allclose(pad.geometry.points["ring_top"], [0.0, 0.222, 0.0])
    # the image, resampled: its top-left pixel is the frame's green, as printed
    assert tuple(pad.texture_rgb[5, 5]) == (20, 120, 40)
    files = write_pad(pad, tmp_path / "out")
    assert {"pad.png", "pad.json", "pad.pdf", "pad_a4_tiles.pdf"} <= set(files)
    back = Pad.load(files["pad.json"])
    assert back.geometry.points.keys() == pad.geometry.points.keys() and back.geometry.border is None
    assert np.array_equal(back.texture_rgb, pad.texture_rgb)
    # bad artwork is refused naming the field, and writes nothing
    for bad, field in (({**spec, "artwork_image": str(tmp_path / "nope.png")}, "pad.artwork_image"),
                       ({**spec, "artwork_points": {"off": [0.5, 0.0]}}, "artwork_points"),
                       ({k: v for k, v in spec.items() if k != "artwork_image"}, "artwork_image"),
                       ({"variant": "paper", "artwork_image": str(art)}, "artwork_image")):
        with pytest.raises(Exception, match=field):
            make_pad(bad, ppm=1000)
    _artwork(tmp_path / "wide.png", (600, 400))
    with pytest.raises(Exception, match="must be square"):
        make_pad({**spec, "artwork_image": str(tmp_path / "wide.png")}, ppm=1000)
    (tmp_path / "bad.yaml").write_text(f"variant: artwork\nartwork_image: {tmp_path / 'nope.png'}\n")
    assert_input_error(run_cli("pad", "make", "--spec", tmp_path / "bad.yaml", "--out", tmp_path / "bad"),
                       "artwork_image")
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())
