"""Nothing a race, a corrupt file or a killed run can do goes unnoticed or breaks a dataset."""
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from benchmarks.corruptions import KINDS
from pad_design.errors import InputError
from render.dataset import Dataset, verify_dataset
from render.generate import generate
from render.spec import DatasetSpec
from tests.conftest import assert_input_error, run_cli

SPEC = {"name": "rel", "seed": 2, "sequences": 2, "pad_ppm": 500,
        "camera": {"width": 64, "height": 64, "fps": 2},
        "trajectory": {"start_height_m": 3.0, "duration_s": [4.0, 4.0], "lateral_offset_m": [0.0, 0.3],
                       "families": ["straight", "spiral"]}}
# damage that localize does not read (it reads the manifest, the sequences it lists and their files)
NOT_READ = {"an extra image", "an unlisted file", "an unfinished .tmp folder"}


def _spec(**over) -> DatasetSpec:
    return DatasetSpec.model_validate({**SPEC, **over})


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    root = tmp_path_factory.mktemp("rel") / "ds"
    generate(_spec(), root, show_progress=False)
    assert verify_dataset(root) == []
    return root


@pytest.mark.parametrize("kind", sorted(KINDS))
def test_verify_reports_every_kind_of_damage_and_localize_refuses_what_it_reads(clean, tmp_path, kind):
    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    KINDS[kind](root)
    problems = verify_dataset(root)
    assert problems, f"{kind}: verify said ok"
    from benchmarks.run import localize_dataset

    if kind in NOT_READ:
        localize_dataset(root, tmp_path / "est", show_progress=False)
    else:
        with pytest.raises(InputError):
            localize_dataset(root, tmp_path / "est", show_progress=False)


def test_damage_through_the_cli_is_one_line_and_a_resume_redoes_it(clean, tmp_path):
    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    KINDS["PNG truncated"](root)
    r = run_cli("dataset", "verify", root)
    assert r.returncode == 1 and "seq_0000/images/000001.png: checksum differs" in r.stdout and not r.stderr
    assert_input_error(run_cli("localize", root, "--out", tmp_path / "est", "--quiet"), "000001.png")
    # taken as it is (--no-verify), the unreadable image is a lost frame with its reason, said on
    # stderr, and every other frame is localized (DESIGN.md: a bad image gets status=lost)
    r = run_cli("localize", root, "--out", tmp_path / "est2", "--quiet", "--no-verify")
    assert r.returncode == 0, r.stderr
    assert "1 image(s) unreadable, localized as lost" in r.stderr and "000001.png: not a readable image" in r.stderr
    from benchmarks.run import read_estimates

    ds = Dataset(root, verify=False)
    for sid in ("seq_0000", "seq_0001"):
        est = read_estimates(tmp_path / "est2" / sid / "estimates.csv")
        assert len(est["frame"]) == len(ds[sid])  # every frame, before and after it
        unreadable = [k for k, why in enumerate(est["reason"]) if why.startswith("image unreadable")]
        assert unreadable == ([1] if sid == "seq_0000" else []), (sid, est["reason"])
        if sid == "seq_0000":
            assert est["status"][1] == "lost" and not np.isfinite(float(est["tx"][1]))
    # a resume re-checks what it keeps: the damaged sequence is rendered again, the other kept
    res = generate(_spec(), root, show_progress=False)
    assert res.rendered == ["seq_0000"] and res.skipped == ["seq_0001"]
    assert verify_dataset(root) == []
    assert json.loads((root / "manifest.json").read_text())["files"] == \
        json.loads((clean / "manifest.json").read_text())["files"]


def test_a_folder_given_for_a_dataset_names_the_datasets_it_holds(clean, tmp_path):
    """A benchmark's results folder, or a sequence, given where a dataset is asked for: the one-line
    error names what to give instead (a new user's first ``hvloc bench diagnose RESULTS`` said only
    "not a generated dataset"); a folder holding none says just that, and nothing is written."""
    run = tmp_path / "run"
    for name in ("rel_a", "rel_b", "rel_c"):
        shutil.copytree(clean, run / "datasets" / name)
    r = run_cli("localize", run, "--out", tmp_path / "est", "--quiet")
    assert_input_error(r, "it holds datasets: give one of")
    assert str(run / "datasets" / "rel_a") in r.stderr and "and 1 more" in r.stderr
    assert_input_error(run_cli("bench", "diagnose", run / "datasets" / "rel_b" / "seq_0000"),
                       f"it is a sequence of {run / 'datasets' / 'rel_b'}")
    (tmp_path / "empty").mkdir()
    r = run_cli("localize", tmp_path / "empty", "--out", tmp_path / "est2", "--quiet")
    assert_input_error(r, "no manifest.json (not a generated dataset)")
    assert "give one of" not in r.stderr and not (tmp_path / "est").exists() and not (tmp_path / "est2").exists()


def _spec_file(tmp_path, seed):
    p = tmp_path / f"spec{seed}.yaml"
    p.write_text(json.dumps({**SPEC, "seed": seed, "sequences": 3}))
    return p


def test_two_writers_into_one_folder_one_is_refused_and_nothing_is_mixed(tmp_path):
    out = tmp_path / "shared"
    out.mkdir()
    cmds = [[sys.executable, "-m", "hvloc.cli", "generate", str(_spec_file(tmp_path, s)), "--out", str(out), "--quiet"]
            for s in (5, 6)]  # both verify clean
    procs = [subprocess.Popen(c, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in cmds]
    res = [(p.wait(timeout=300), p.stderr.read()) for p in procs]
    codes = sorted(c for c, _ in res)
    assert codes == [0, 2], res
    loser = next(err for c, err in res if c == 2)
    assert len(loser.strip().splitlines()) == 1 and ("another hvloc process" in loser or "another spec" in loser), loser
    assert verify_dataset(out) == []


def _children(pid: int) -> list:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_kill_9_of_the_parent_stops_its_workers_and_a_rerun_completes_identically(tmp_path):
    spec_file = _spec_file(tmp_path, 7)
    full = tmp_path / "full"
    assert run_cli("generate", spec_file, "--out", full, "--quiet").returncode == 0
    out = tmp_path / "killed"
    p = subprocess.Popen([sys.executable, "-m", "hvloc.cli", "generate", str(spec_file), "--out", str(out), "--quiet",
                          "--workers", "2"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    workers = []
    while time.time() < deadline:  # kill once the workers are rendering
        workers = [c for c in _children(p.pid) if b"multiprocessing" in Path(f"/proc/{c}/cmdline").read_bytes()]
        if len(workers) >= 2 and list(out.glob(".tmp-seq_*/images/*.png")):
            break
        time.sleep(0.05)
    assert workers, "no workers started"
    os.kill(p.pid, signal.SIGKILL)
    p.wait()
    time.sleep(2.0)
    assert not [w for w in workers if _alive(w)], "workers outlived their killed parent"
    assert verify_dataset(out)  # incomplete, and verify says so
    r = run_cli("generate", spec_file, "--out", out, "--quiet", "--workers", "2")
    assert r.returncode == 0, r.stderr
    assert verify_dataset(out) == []
    assert json.loads((out / "manifest.json").read_text())["files"] == \
        json.loads((full / "manifest.json").read_text())["files"]


def _unit_that_dies(i: int) -> int:
    import os
    import signal

    if i == 2:
        os.kill(os.getpid(), signal.SIGKILL)  # as the OOM killer or a crash in native code would
    return i


def test_a_worker_that_dies_fails_the_run_instead_of_hanging_it():
    """multiprocessing.Pool replaced a dead worker and waited for its unit forever (a bench run hung
    for 40 minutes after a native crash); now the run fails at once, saying why."""
    import time

    from render.executor import run_units

    t0 = time.time()
    with pytest.raises(RuntimeError, match="worker process died"):
        list(run_units(_unit_that_dies, [(i,) for i in range(6)], workers=2))
    assert time.time() - t0 < 120
    assert sorted(run_units(_unit_that_dies, [(i,) for i in (0, 1, 3)], workers=2)) == [0, 1, 3]


@pytest.mark.parametrize("field,value,names", [
    ("dist", [float("nan"), 0.0, 0.0, 0.0, 0.0], "dist[0]"),
    ("fx", -300.0, "fx, fy must be positive"),
    ("fps", 0.0, "fps 0.0 is not a frame rate"),
    ("T_B_C", [[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "T_B_C is not a rigid transform"),
    ("T_B_C", [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]], "T_B_C is not a rigid transform"),
    ("exposure_s", -0.01, "exposure_s -0.01 is not a time"),
    ("rolling_shutter_line_s", "fast", "rolling_shutter_line_s 'fast' is not a time"),
    ("imu_time_offset_s", float("inf"), "imu_time_offset_s inf is not a time"),
])
def test_a_camera_no_camera_has_is_refused_in_one_line_naming_its_field(clean, tmp_path, field, value, names):
    """camera.json taken as it is (--no-verify) with a number no camera has: a NaN lens
    coefficient, a mount scaled or mirrored, no frame rate, a negative exposure, a shutter or clock
    offset that is no number.  Read without a word, a NaN in dist or a scaled T_B_C lost or rejected
    every frame of the sequence; each is now one line naming the file and the field, exit 2, and
    nothing written.  An imported flight's unknown exposure (null) is no error."""
    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    path = root / "seq_0000" / "camera.json"
    info = json.loads(path.read_text())
    info[field] = value
    path.write_text(json.dumps(info))
    r = run_cli("localize", root, "--out", tmp_path / "est", "--quiet", "--no-verify")
    assert_input_error(r, names)
    assert "seq_0000" in r.stderr and "camera.json" in r.stderr and not (tmp_path / "est" / "seq_0000").exists()
    info = json.loads((clean / "seq_0000" / "camera.json").read_text())
    path.write_text(json.dumps({**info, "exposure_s": None}))
    r = run_cli("localize", root, "--out", tmp_path / "est2", "--quiet", "--no-verify")
    assert r.returncode == 0, r.stderr


@pytest.mark.parametrize("damage,names", [("swap", "t goes back at row 4"), ("nan", "row 3's t is nan, not a time")])
def test_imu_rows_out_of_time_order_are_refused_in_one_line_naming_the_row(clean, tmp_path, damage, names):
    """imu.csv taken as it is (--no-verify) with two rows swapped, or a time that is no number:
    every reader takes the rows in time order, and shuffled they were read without a word (22 of
    107 frames rejected).  One line naming the file and the first bad row, exit 2."""
    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    path = root / "seq_0000" / "imu.csv"
    lines = path.read_text().splitlines()
    if damage == "swap":  # data rows 3 and 4 (lines 4 and 5)
        lines[3], lines[4] = lines[4], lines[3]
    else:
        cells = lines[3].split(",")
        lines[3] = ",".join(["nan"] + cells[1:])
    path.write_text("\n".join(lines) + "\n")
    r = run_cli("localize", root, "--out", tmp_path / "est", "--quiet", "--no-verify")
    assert_input_error(r, names)
    assert "seq_0000/imu.csv" in r.stderr and not (tmp_path / "est" / "seq_0000").exists()


@pytest.mark.parametrize("damage,names", [
    ("swap", "row 3 is frame 2, the dataset's row 3 frame 1"),
    ("tx=abc", "column 'tx' holds 'abc', not a number"),
    ("status=great", "row 3's status is 'great', not one of ok, rejected, lost"),
    ("frame=77", "row 3 is frame 77"),
    ("drop", "2 frames, the dataset's sequence has "),
    ("ok without pose", "row 3 is ok without a finite pose"),
])
def test_a_localizers_estimates_no_localizer_writes_are_refused_by_score_naming_the_row(clean, tmp_path, damage,
                                                                                          names):
    """``hvloc bench score`` reads an estimates.csv that any localizer may have written.  A word
    in a number's column ended it in a traceback; two rows swapped, a frame number that is not the
    dataset's, an unknown status or an ``ok`` without a pose were scored without a word (each frame
    against another's labels, or counted available).  Each is one line naming the file and row."""
    from benchmarks.run import ESTIMATE_COLUMNS
    from render.dataset import read_csv_columns, write_csv

    root = tmp_path / "ds"
    shutil.copytree(clean, root)
    assert run_cli("localize", root, "--out", tmp_path / "est", "--quiet").returncode == 0
    path = tmp_path / "est" / "seq_0000" / "estimates.csv"
    c = read_csv_columns(path, ("phase", "status", "method", "reason"))
    rows = [[c[k][i] for k in ESTIMATE_COLUMNS] for i in range(len(c["frame"]))]
    assert len(rows) >= 3
    col = {k: i for i, k in enumerate(ESTIMATE_COLUMNS)}
    if damage == "swap":
        rows[1], rows[2] = rows[2], rows[1]
    elif damage == "drop":
        rows = rows[:2]
    elif damage == "ok without pose":
        rows[1][col["status"]], rows[1][col["tx"]] = "ok", float("nan")
    else:
        key, value = damage.split("=")
        rows[1][col[key]] = value
    write_csv(path, ESTIMATE_COLUMNS, rows)
    r = run_cli("bench", "score", root, tmp_path / "est")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert names in r.stderr and "seq_0000/estimates.csv" in r.stderr, r.stderr
