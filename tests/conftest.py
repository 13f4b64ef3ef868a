import os

os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def pad():
    """The default (paper) pad at 2000 px/m."""
    from pad_design import make_pad

    return make_pad()
