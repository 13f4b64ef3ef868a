import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def pad():
    """The default (paper) pad at 2000 px/m."""
    from pad_design import make_pad

    return make_pad()


def run_cli(*args, **kw):
    """Run the real ``hvloc`` front door in a subprocess."""
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "hvloc.cli", *map(str, args)], capture_output=True, text=True, **kw)


def assert_input_error(result, names: str) -> None:
    """Exit code 2 and exactly one line on stderr that names the field."""
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and names in lines[0], result.stderr
