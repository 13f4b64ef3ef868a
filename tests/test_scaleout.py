"""Results are the same, byte for byte, whichever executor and worker count made them."""
import json

from render.generate import generate
from render.spec import DatasetSpec

# 3 m in 8 s (in 4 s, with min-jerk moves, and in 6 s with min-snap ones, whose peak acceleration is 1.3x,
# the hover_correct sequence's first step fell faster than gravity: upside down, refused)
SPEC = {"name": "scale", "seed": 9, "sequences": 3, "pad_ppm": 500, "camera": {"width": 96, "height": 96, "fps": 3},
        "trajectory": {"start_height_m": 3.0, "duration_s": [8.0, 8.0], "lateral_offset_m": [0.0, 0.3]}}


def _files(root):
    return json.loads((root / "manifest.json").read_text())["files"]


def test_a_real_local_ray_instance_renders_and_localizes_the_same_bytes(tmp_path):
    import ray

    spec = DatasetSpec.model_validate(SPEC)
    generate(spec, tmp_path / "local", workers=1, show_progress=False)
    try:
        generate(spec, tmp_path / "ray", workers=2, show_progress=False, executor="ray")
        assert ray.is_initialized()  # it really ran on Ray
        assert _files(tmp_path / "ray") == _files(tmp_path / "local")
        from render.dataset import Dataset
        from render.executor import run_units

        from benchmarks.suite import _localize_unit

        setups = [({}, True, "hierarchical")]
        out = {}
        for ex, root in (("local", tmp_path / "local"), ("ray", tmp_path / "ray")):
            units = [(str(root), sid, setups, [str(tmp_path / f"est-{ex}" / sid)], True)
                     for sid in Dataset(root).sequence_ids]
            assert sum(run_units(_localize_unit, units, 2, ex)) == sum(s["frames"] for s in
                                                                       json.loads((root / "manifest.json").read_text())["sequences"])
            out[ex] = {sid: (tmp_path / f"est-{ex}" / sid / "estimates.tum").read_text() for sid in Dataset(root).sequence_ids}
        assert out["ray"] == out["local"]
    finally:
        ray.shutdown()
