"""Landing-pad designer: spec, exact 3D feature geometry (``pad.json``), texture and printable output."""
from .errors import InputError
from .pad import DEFAULT_PPM, Pad, make_pad, write_pad
from .spec import PadSpec

__all__ = ["InputError", "Pad", "PadSpec", "make_pad", "write_pad", "DEFAULT_PPM"]
