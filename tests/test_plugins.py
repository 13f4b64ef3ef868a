"""Localizers from elsewhere: named in a suite by import path, run through ``hvloc bench run``
with the same harness, metrics and "never raises" contract as hvloc's own, optionally behind
hvloc's false-pose gates."""
import json
from pathlib import Path

import numpy as np
import pytest

from hvloc.localizer import Estimate
from tests.conftest import assert_input_error, run_cli

REPO = Path(__file__).parent.parent


class Flaky:
    """A badly behaved localizer: it raises, returns the wrong type, or claims a pose 30 m off."""

    PAD_VARIANTS = ("paper",)

    def __init__(self, pad, camera, config=None, T_B_C=None):
        self.n = 0

    def process(self, image, t, imu=None):
        self.n += 1
        if self.n % 4 == 1:
            raise RuntimeError("segfault-ish")
        if self.n % 4 == 2:
            return "a pose"
        T = np.eye(4)
        T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking down
        T[:3, 3] = (30.0, 0.0, 2.0) if self.n % 8 == 3 else (0.0, 0.0, 2.0)
        return Estimate(t, "adjustment", "ok", T, 4, 0.5, method="flaky")


SUITE = """name: plugins
datasets:
  - spec: data_specs/tiny.yaml
    sequences: 1
    overrides:
      name: plugtiny
      camera: {width: 160, height: 160, fps: 5}
      trajectory: {start_height_m: 3.0, duration_s: [6.0, 6.0], lateral_offset_m: [0.0, 0.2], families: [straight]}
localizers:
  - {name: hvloc, kind: hierarchical}
  - {name: colour_quad, kind: "examples.colour_quad:ColourQuad"}
  - {name: colour_quad_gated, kind: "examples.colour_quad:ColourQuad", gates: true}
  - {name: flaky, kind: "tests.test_plugins:Flaky"}
  - {name: flaky_gated, kind: "tests.test_plugins:Flaky", gates: true}
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("plugins")
    (d / "plugins.yaml").write_text(SUITE)
    r = run_cli("bench", "run", d / "plugins.yaml", "--out", d / "out", "--workers", "2", "-q", cwd=REPO)
    assert r.returncode == 0, r.stderr
    return d / "out", json.loads((d / "out" / "results.json").read_text())


def _rows(out, name):
    from benchmarks.run import read_estimates

    (path,) = (out / "estimates" / name).glob("*/seq_*/estimates.csv")
    return read_estimates(path)


def test_a_localizer_from_elsewhere_is_scored_beside_hvloc(run):
    out, res = run
    s = res["summary"]
    assert set(s) == {"hvloc", "colour_quad", "colour_quad_gated", "flaky", "flaky_gated"}
    frames = s["hvloc"]["all"]["frames"]
    assert s["colour_quad"]["all"]["frames"] == frames > 20
    assert s["colour_quad"]["all"]["availability"] > 0.3  # a naive method, but a working one
    assert res["localizer_setup"]["colour_quad"]["kind"] == "examples.colour_quad:ColourQuad"
    assert (out / "report.md").read_text().count("colour_quad") >= 2


def test_a_localizer_that_raises_or_lies_never_breaks_the_run(run):
    out, res = run
    c = _rows(out, "flaky")
    reasons = " ".join(c["reason"][c["status"] == "lost"])
    assert "RuntimeError: segfault-ish" in reasons and "not an Estimate" in reasons
    n = len(c["status"])
    assert (c["status"] == "lost").sum() == (n + 1) // 4 + (n + 2) // 4  # every raise and every wrong type
    # the 30 m jumps it claims are false accepts without gates, and caught by hvloc's gates in front
    assert res["summary"]["flaky"]["all"]["false_accepts"] > 0
    g = _rows(out, "flaky_gated")
    rejected = g["reason"][g["status"] == "rejected"]
    assert len(rejected) > 0 and all("moved" in r or "tilt" in r or "vision-IMU" in r for r in rejected)
    assert res["summary"]["flaky_gated"]["all"]["false_accepts"] < res["summary"]["flaky"]["all"]["false_accepts"]
    # gates reject, never invent: what the gated run accepts the plain run accepted too
    assert set(np.flatnonzero(g["status"] == "ok")) <= set(np.flatnonzero(c["status"] == "ok"))
    q = _rows(out, "colour_quad_gated")
    assert set(np.flatnonzero(q["status"] == "ok")) <= set(np.flatnonzero(_rows(out, "colour_quad")["status"] == "ok"))


def test_a_kind_that_cannot_be_imported_is_refused_naming_it(tmp_path):
    bad = SUITE.replace("tests.test_plugins:Flaky", "tests.test_plugins:Missing", 1)
    (tmp_path / "s.yaml").write_text(bad)
    r = run_cli("bench", "run", tmp_path / "s.yaml", "--out", tmp_path / "out", cwd=REPO)
    assert_input_error(r, "localizers.3.kind")
    assert "Missing" in r.stderr and not (tmp_path / "out").exists()
    (tmp_path / "t.yaml").write_text(SUITE.replace("tests.test_plugins:Flaky", "no_such_module_xyz:Thing", 1))
    assert_input_error(run_cli("bench", "run", tmp_path / "t.yaml", "--out", tmp_path / "o2", cwd=REPO), "no_such_module_xyz")


def test_a_pad_from_your_own_artwork_is_rendered_labelled_and_scored(tmp_path):
    """The whole path for a user's pad: a suite names a dataset whose pad is the user's image (with
    the points it names), it renders with labels that pass verify's checks (the image check
    included), and a localizer written for it (examples/artwork_match.py: SIFT against the pad's
    texture) is scored on it, plain and behind hvloc's gates; hvloc's own localizer says plainly
    that it cannot run on such a pad."""
    from hvloc.localizer import HierarchicalLocalizer
    from render.dataset import Dataset, verify_dataset
    from tests.test_pad import _artwork

    art = _artwork(tmp_path / "art.png")
    (tmp_path / "art.yaml").write_text(f"""name: artwork
datasets:
  - spec: data_specs/tiny.yaml
    sequences: 1
    overrides:
      name: arttiny
      camera: {{width: 240, height: 240, fps: 5}}
      pad: {{variant: artwork, side_m: 0.8, artwork_image: "{art}", artwork_points: {{ring_top: [0.0, 0.222]}}}}
      trajectory: {{start_height_m: 3.0, duration_s: [6.0, 6.0], lateral_offset_m: [0.0, 0.2], families: [straight]}}
localizers:
  - {{name: artwork_match, kind: "examples.artwork_match:ArtworkMatch"}}
  - {{name: artwork_match_gated, kind: "examples.artwork_match:ArtworkMatch", gates: true}}
""")
    r = run_cli("bench", "run", tmp_path / "art.yaml", "--out", tmp_path / "out", "--workers", "2", "-q", cwd=REPO)
    assert r.returncode == 0, r.stderr
    (ds_root,) = (tmp_path / "out" / "datasets").iterdir()
    assert verify_dataset(ds_root) == []
    seq = Dataset(ds_root)[0]
    assert seq.pad.geometry.variant == "artwork" and "ring_top" in seq.pad.geometry.points
    s = json.loads((tmp_path / "out" / "results.json").read_text())["summary"]
    assert s["artwork_match"]["all"]["frames"] == len(seq) > 20
    assert s["artwork_match"]["all"]["availability"] > 0.5 and s["artwork_match_gated"]["all"]["false_accepts"] == 0
    with pytest.raises(ValueError, match="needs hvloc's pad"):
        HierarchicalLocalizer(seq.pad, seq.camera)
    from tests.conftest import assert_input_error

    assert_input_error(run_cli("localize", ds_root, "--out", tmp_path / "est"), "a pad with hvloc's border and cue")
    assert not (tmp_path / "est").exists()


def test_an_import_path_is_found_in_the_working_directory_as_python_m_would(tmp_path):
    """The `hvloc` console script does not put the working directory on sys.path (python -m does):
    `--localizer mylocs:Loc` from the folder that holds mylocs.py failed with "No module named"."""
    import subprocess
    import sys

    (tmp_path / "mylocs.py").write_text("class Loc:\n    def process(self, image, t, imu=None):\n        pass\n")
    code = ("import sys; sys.path[:] = [p for p in sys.path if p not in ('', '.')]\n"
            "from benchmarks.run import localizer_class\nprint(localizer_class('mylocs:Loc').__name__)")
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                       env={**__import__("os").environ, "PYTHONPATH": str(REPO)})
    assert r.returncode == 0 and r.stdout.strip() == "Loc", r.stderr
