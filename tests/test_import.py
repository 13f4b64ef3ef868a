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
    them), and the localizer's estimates are identical bit for bit."""
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
