"""hvloc import: a recording (images or a video, a calibration, IMU, ground truth) becomes a dataset
that verifies and scores like the one it was made from."""
import json
import shutil

import cv2
import numpy as np
import pytest

from render.dataset import Dataset, read_tum, verify_dataset, write_tum
from tests.conftest import assert_input_error, run_cli

LABELS = ["tx", "ty", "tz", "qx", "qy", "qz", "qw", "c0u", "c0v", "c2u", "c2v", "height_above_pad", "module_px",
          "pad_visible_fraction", "markers_visible", "pad_fully_visible"]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """A rendered descent written out as a flight log would be: PNG frames, an MJPG video, TUM ground
    truth, imu.csv and a ROS CameraInfo calibration."""
    from render.generate import generate
    from render.spec import DatasetSpec, load_dataset_spec

    base = tmp_path_factory.mktemp("rec")
    tiny = json.loads(load_dataset_spec("data_specs/tiny.yaml").canonical_json())
    # (at the pad's default raster, as an import draws it: tiny's 1000 px/m texture would be placed
    # otherwise by the texture's drawing near the ground)
    tiny.pop("pad_ppm", None)
    spec = DatasetSpec.model_validate({**tiny, "sequences": 1, "seed": 4, "environment": {"distractors": {"boxes": [0, 0], "decoy_patches": [0, 0], "decoy_markers": [0, 0]}},
                                       "trajectory": {**tiny["trajectory"], "start_height_m": 3.0,
                                                      "duration_s": [5.0, 5.0], "lateral_offset_m": [0.0, 0.3]}})
    generate(spec, base / "orig", show_progress=False)
    seq = base / "orig" / "seq_0000"
    cam = json.loads((seq / "camera.json").read_text())
    (base / "ost.yaml").write_text(
        f"image_width: {cam['width']}\nimage_height: {cam['height']}\ncamera_name: sim\n"
        f"camera_matrix: {{rows: 3, cols: 3, data: [{cam['fx']}, 0, {cam['cx']}, 0, {cam['fy']}, {cam['cy']}, 0, 0, 1]}}\n"
        f"distortion_model: plumb_bob\ndistortion_coefficients: {{rows: 1, cols: 5, data: {list(cam['dist'])}}}\n")
    shutil.copytree(seq / "images", base / "frames")
    shutil.copy(seq / "groundtruth.tum", base / "gt.tum")
    shutil.copy(seq / "imu.csv", base / "imu.csv")
    video = cv2.VideoWriter(str(base / "flight.avi"), cv2.VideoWriter_fourcc(*"MJPG"), cam["fps"],
                            (cam["width"], cam["height"]))
    for p in sorted((base / "frames").glob("*.png")):
        video.write(cv2.imread(str(p)))
    video.release()
    return base, cam


def _import(base, out, *extra):
    r = run_cli("import", *extra, "--calibration", base / "ost.yaml", "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    assert verify_dataset(out) == []
    return Dataset(out)["seq_0000"]


def _localize(seq):
    from benchmarks.run import localize_sequence
    from hvloc.config import LocalizerConfig

    return localize_sequence(seq, LocalizerConfig())


def test_imported_frames_and_ground_truth_are_the_rendered_dataset_again(recording, tmp_path):
    """Its own PNGs, TUM and IMU imported: labels equal to 1e-9 (the image check of verify passes on
    them), and the localizer's estimates are identical bit for bit (the recording drawn at the
    pad's default raster, as the import's pad is: the texture placed near the ground from tiny's
    1000 px/m raster put one pose 2 mm elsewhere)."""
    base, _ = recording
    orig = Dataset(base / "orig")["seq_0000"]
    seq = _import(base, tmp_path / "ds", base / "frames", "--fps", "10", "--groundtruth", base / "gt.tum",
                  "--imu", base / "imu.csv")
    for c in LABELS:
        np.testing.assert_allclose(np.asarray(seq.columns[c], float), np.asarray(orig.columns[c], float),
                                   atol=1e-9, err_msg=c)
    assert list(seq.columns["phase_gt"]) == list(orig.columns["phase_gt"])
    for a, b in zip(_localize(orig), _localize(seq)):
        assert a.status == b.status and ((a.cam2pad is None and b.cam2pad is None) or np.array_equal(a.cam2pad, b.cam2pad))
    assert seq.meta["imported"]["ground_truth"] == "camera" and seq.meta["imported"]["sha256"]["groundtruth"]


def test_body_ground_truth_through_the_mount_gives_the_same_labels(recording, tmp_path):
    from hvloc.geometry import invert, transform_from_tum, tum_from_transform

    base, cam = recording
    T_B_C = np.asarray(cam["T_B_C"])
    gt = read_tum(base / "gt.tum")
    body = [tum_from_transform(transform_from_tum(r[1:]) @ invert(T_B_C)) for r in gt]  # T_P_B
    write_tum(tmp_path / "body.tum", gt[:, 0] - 0.25, body, "T_P_B")  # on another clock
    seq = _import(base, tmp_path / "ds", base / "frames", "--fps", "10", "--groundtruth", tmp_path / "body.tum",
                  "--gt-body", "--gt-time-offset", "0.25")
    orig = Dataset(base / "orig")["seq_0000"]
    np.testing.assert_allclose(seq.cam2pad, orig.cam2pad, atol=1e-9)
    assert list(seq.columns["phase_gt"]) == list(orig.columns["phase_gt"])


def test_a_video_scores_like_its_frames_within_the_codec(recording, tmp_path):
    from benchmarks.run import score_dataset, write_estimates

    base, _ = recording
    seqs = {"png": _import(base, tmp_path / "png", base / "frames", "--fps", "10", "--groundtruth", base / "gt.tum",
                           "--imu", base / "imu.csv"),
            "video": _import(base, tmp_path / "video", base / "flight.avi", "--groundtruth", base / "gt.tum",
                             "--imu", base / "imu.csv")}  # fps from the video
    scores = {}
    for k, seq in seqs.items():
        write_estimates(tmp_path / f"est_{k}" / "seq_0000", _localize(seq))
        scores[k] = score_dataset(tmp_path / k, tmp_path / f"est_{k}")["summary"]
    a, b = scores["png"]["all"], scores["video"]["all"]
    assert a["frames"] == b["frames"] == len(seqs["png"])
    assert abs(a["availability"] - b["availability"]) <= 0.05 and a["false_accepts"] == b["false_accepts"] == 0
    adj_a, adj_b = scores["png"]["gt:adjustment"]["pos_err_m_rmse"], scores["video"]["gt:adjustment"]["pos_err_m_rmse"]
    assert adj_b < 2 * adj_a + 0.005, (adj_a, adj_b)  # JPEG costs accuracy, not the method


def test_without_ground_truth_or_imu_it_localizes_and_says_what_it_cannot_score(recording, tmp_path):
    base, _ = recording
    _import(base, tmp_path / "ds", base / "flight.avi")
    r = run_cli("localize", tmp_path / "ds", "--out", tmp_path / "est", "--quiet")
    assert r.returncode == 0, r.stderr
    r = run_cli("bench", "score", tmp_path / "ds", tmp_path / "est")
    assert r.returncode == 0, r.stderr
    assert "have no ground truth" in r.stdout and "| estimates | all |" in r.stdout
    assert "| estimates | approaching |" not in r.stdout


def test_bad_recordings_are_refused_naming_what_is_wrong_and_write_nothing(recording, tmp_path):
    base, _ = recording
    small = tmp_path / "small"
    small.mkdir()
    cv2.imwrite(str(small / "0.png"), np.zeros((100, 120, 3), np.uint8))
    cases = [((small, "--fps", "10"), "frame 0 is 120x100"),
             ((base / "frames",), "--fps"),
             ((base / "frames", "--fps", "10", "--groundtruth", base / "gt.tum", "--gt-time-offset", "100"),
              "--gt-time-offset"),
             ((base / "nothing.mp4",), "no such video"),
             ((base / "flight.avi", "--gt-body"), "--gt-body")]
    for i, (args, says) in enumerate(cases):
        out = tmp_path / f"o{i}"
        r = run_cli("import", *args, "--calibration", base / "ost.yaml", "--out", out, "--quiet")
        assert_input_error(r, says)
        assert not out.exists() or not any(out.iterdir()), f"{says}: left {list(out.iterdir())}"


def test_a_rolling_shutter_stated_at_import_reaches_the_localizer(recording, tmp_path):
    from benchmarks.run import make_localizer
    from hvloc.config import LocalizerConfig

    base, cam = recording
    line_s = 0.5 / cam["fps"] / cam["height"]  # read in half a frame interval
    seq = _import(base, tmp_path / "ds", base / "frames", "--fps", "10", "--line-time-s", str(line_s), "--ref-row", "3")
    info = json.loads((tmp_path / "ds" / "seq_0000" / "camera.json").read_text())
    assert info["rolling_shutter_line_s"] == seq.line_s == line_s and info["rolling_shutter_ref_row"] == seq.ref_row == 3.0
    manifest = json.loads((tmp_path / "ds" / "manifest.json").read_text())
    assert manifest["spec"]["camera"]["rolling_shutter_line_s"] == line_s  # the recording's spec says so too
    shutter = make_localizer("hierarchical", seq, LocalizerConfig()).shutter
    assert shutter.active and (shutter.line_s, shutter.ref_row) == (line_s, 3.0)
    plain = _import(base, tmp_path / "plain", base / "frames", "--fps", "10")
    assert plain.line_s == 0.0 and not make_localizer("hierarchical", plain, LocalizerConfig()).shutter.active
    cases = [(("--line-time-s", "-1e-5"), "--line-time-s"),
             (("--line-time-s", str(2.0 / cam["fps"] / cam["height"])), "within a frame interval"),
             (("--ref-row", "3"), "--ref-row: goes with --line-time-s"),
             (("--line-time-s", str(line_s), "--ref-row", str(cam["height"])), "--ref-row")]
    for i, (args, says) in enumerate(cases):
        out = tmp_path / f"o{i}"
        r = run_cli("import", base / "frames", "--fps", "10", *args, "--calibration", base / "ost.yaml", "--out", out,
                    "--quiet")
        assert_input_error(r, says)
        assert not out.exists() or not any(out.iterdir()), f"{says}: left {list(out.iterdir())}"


def test_an_exposure_stated_at_import_reaches_the_localizer(recording, tmp_path):
    """A camera's exposure (its metadata) says how far motion smears a frame: the localizer draws the
    pad smeared over it.  Not stated, camera.json says it is not known; one no frame has is refused
    naming the option, and nothing is written."""
    from benchmarks.run import make_localizer
    from hvloc.config import LocalizerConfig

    base, cam = recording
    seq = _import(base, tmp_path / "ds", base / "frames", "--fps", "10", "--exposure-s", "0.02")
    assert json.loads((tmp_path / "ds" / "seq_0000" / "camera.json").read_text())["exposure_s"] == 0.02
    assert json.loads((tmp_path / "ds" / "manifest.json").read_text())["spec"]["camera"]["exposure_s"] == 0.02
    assert seq.exposure_s == 0.02 and make_localizer("hierarchical", seq, LocalizerConfig()).exposure_s == 0.02
    plain = _import(base, tmp_path / "plain", base / "frames", "--fps", "10")
    assert json.loads((tmp_path / "plain" / "seq_0000" / "camera.json").read_text())["exposure_s"] is None
    assert plain.exposure_s == 0.0 and make_localizer("hierarchical", plain, LocalizerConfig()).exposure_s == 0.0
    for i, bad in enumerate(("0", "-0.01", "0.2", "nan")):  # 0.2 s: longer than a frame interval at 10 fps
        out = tmp_path / f"o{i}"
        r = run_cli("import", base / "frames", "--fps", "10", "--exposure-s", bad, "--calibration", base / "ost.yaml",
                    "--out", out, "--quiet")
        assert_input_error(r, "--exposure-s")
        assert not out.exists() or not any(out.iterdir())


def test_a_cameras_response_stated_at_import_reaches_the_localizer(recording, tmp_path):
    """A photometric calibration (``--response GAMMA [SHARPEN [SIGMA_PX]]``) is written to camera.json's
    ``response`` and given to the localizer's design fit; not stated, none is.  One that no camera
    has is refused naming the option, and nothing is written."""
    from benchmarks.run import make_localizer
    from hvloc.config import LocalizerConfig

    base, cam = recording
    seq = _import(base, tmp_path / "ds", base / "frames", "--fps", "10", "--response", "2.4", "0.3")
    assert json.loads((tmp_path / "ds" / "seq_0000" / "camera.json").read_text())["response"] == \
        {"gamma": 2.4, "sharpen": 0.3, "sharpen_sigma_px": 1.0}
    assert seq.response == (2.4, 0.3, 1.0) and make_localizer("hierarchical", seq, LocalizerConfig()).response == (2.4, 0.3, 1.0)
    one = _import(base, tmp_path / "one", base / "frames", "--fps", "10", "--response", "2.2")
    assert one.response == (2.2, 0.0, 1.0)
    plain = _import(base, tmp_path / "plain", base / "frames", "--fps", "10")
    assert "response" not in json.loads((tmp_path / "plain" / "seq_0000" / "camera.json").read_text())
    assert plain.response is None and make_localizer("hierarchical", plain, LocalizerConfig()).response is None
    for i, bad in enumerate((["-2.2"], ["2.2", "-1"], ["2.2", "0.3", "0"], ["nan"], ["2.2", "0.3", "1", "4"])):
        out = tmp_path / f"o{i}"
        r = run_cli("import", base / "frames", "--fps", "10", "--response", *bad, "--calibration", base / "ost.yaml",
                    "--out", out, "--quiet")
        assert_input_error(r, "--response")
        assert not out.exists() or not any(out.iterdir())


def test_numbered_images_keep_their_frame_numbers_and_times_across_dropped_frames(recording, tmp_path):
    """A recording that dropped frames: the images named by frame number keep it, so each is labelled
    at its own time (not shifted into the gap)."""
    base, _ = recording
    kept = tmp_path / "frames"
    shutil.copytree(base / "frames", kept)
    for name in ("000005.png", "000006.png", "000007.png", "000020.png"):
        (kept / name).unlink()
    seq = _import(base, tmp_path / "ds", kept, "--fps", "10", "--groundtruth", base / "gt.tum")
    orig = Dataset(base / "orig")["seq_0000"]
    frames = seq.columns["frame"].astype(int)
    assert 5 not in frames and 20 not in frames and len(frames) == len(orig) - 4
    np.testing.assert_allclose(seq.t, frames / 10.0)
    np.testing.assert_allclose(seq.cam2pad, orig.cam2pad[frames], atol=1e-9)


@pytest.mark.parametrize("with_numbers", [False, True])
def test_timestamps_bring_back_dropped_frames_whatever_the_files_are_called(recording, tmp_path, with_numbers):
    """Frames named without their numbers, four of them dropped, the capture times (jittered, on a
    clock that starts at 1000 s) in a file: the frame numbers and times come back, ground truth and
    IMU on the same clock line up, and the labels are the original's."""
    base, _ = recording
    orig = Dataset(base / "orig")["seq_0000"]
    kept = tmp_path / "frames"
    kept.mkdir()
    rng = np.random.default_rng(3)
    frames = [k for k in range(len(orig)) if k not in (5, 6, 7, 20)]
    t = np.arange(len(orig)) / 10.0 + rng.normal(0.0, 0.01, len(orig))  # 10 ms of jitter at 10 Hz
    t[0] = 0.0
    for i, k in enumerate(frames):
        shutil.copy(base / "frames" / f"{k:06d}.png", kept / f"shot_{chr(97 + i // 26)}{chr(97 + i % 26)}.png")
    clock = 1000.0
    lines = [f"{k} {clock + t[k]:.6f}" if with_numbers else f"{clock + t[k]:.6f}" for k in frames]
    (tmp_path / "times.txt").write_text("# capture times\n" + "\n".join(lines) + "\n")
    gt = read_tum(base / "gt.tum")
    write_tum(tmp_path / "gt.tum", gt[:, 0] + clock, gt[:, 1:], "T_P_C on the frames' clock")
    seq = _import(base, tmp_path / "ds", kept, "--timestamps", tmp_path / "times.txt",
                  "--groundtruth", tmp_path / "gt.tum")
    np.testing.assert_array_equal(seq.columns["frame"].astype(int), frames)
    np.testing.assert_allclose(seq.t, t[frames], atol=1e-6)
    assert json.loads((tmp_path / "ds" / "seq_0000" / "meta.json").read_text())["imported"]["time_zero_s"] == clock
    # the pose at each jittered time lies between the original's neighbouring frames
    err = np.linalg.norm(seq.cam2pad[:, :3, 3] - orig.cam2pad[frames][:, :3, 3], axis=1)
    step = np.linalg.norm(np.diff(orig.cam2pad[:, :3, 3], axis=0), axis=1).max()
    assert err.max() < step, (err.max(), step)


def test_timestamps_that_cannot_be_frames_are_refused(recording, tmp_path):
    base, _ = recording
    n = len(list((base / "frames").glob("*.png")))
    cases = {"short.txt": ("0.0\n0.1\n", f"2 times for {n} frames"),
             "back.txt": ("".join(f"{0.1 * k if k != 3 else 0.05}\n" for k in range(n)), "increasing"),
             "words.txt": ("0.0\nnoon\n" + "".join(f"{0.1 * k}\n" for k in range(2, n)), "line 2"),
             "clash.txt": ("".join(f"{0.1 * k + (0.06 if k == 4 else 0.0)}\n" for k in range(n)), "one frame number")}
    for i, (name, (text, says)) in enumerate(cases.items()):
        (tmp_path / name).write_text(text)
        out = tmp_path / f"o{i}"
        r = run_cli("import", base / "frames", "--fps", "10", "--timestamps", tmp_path / name,
                    "--calibration", base / "ost.yaml", "--out", out, "--quiet")
        assert_input_error(r, says)
        assert not out.exists() or not any(out.iterdir())
