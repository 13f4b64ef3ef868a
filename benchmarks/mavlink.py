"""Accepted estimates as MAVLink ``LANDING_TARGET`` messages (``hvloc localize --mavlink``).

The message (id 149, common dialect; encoded with ``pymavlink``) as ArduPilot's precision
landing reads it (``PLND_TYPE = 1``, MAVLink): ``frame = MAV_FRAME_BODY_FRD``,
``position_valid = 1`` and ``x, y, z`` the pad centre relative to the vehicle in its body frame,
forward-right-down (hvloc's body frame is FLU: y and z change sign); ``distance`` the length of
that vector; ``q`` (w, x, y, z) the pad frame's orientation in that body frame;
``angle_x, angle_y`` the pad centre's angular offset from the optical axis along the image's x
and y; ``size_x, size_y`` the pad's angular size; ``type`` = vision fiducial.  The message has no
covariance field: the covariance stays in ``estimates.csv``.

Targets: ``udp:HOST:PORT`` sends each message as one UDP datagram (what a flight stack or
MAVProxy listens on); any other value is a file path written as a ``.tlog`` (each message after
its 8-byte big-endian microsecond time, the form ``mavlogdump.py`` and ``pymavlink`` read).
``time_usec`` is the frame's time since the sequence start plus ``epoch_s`` (0: time since boot).
"""
from __future__ import annotations

import math
import socket
import struct
from pathlib import Path

import numpy as np

from hvloc.geometry import invert, quat_xyzw_from_matrix
from pad_design.errors import InputError

FLU_TO_FRD = np.diag([1.0, -1.0, -1.0])


def landing_target_fields(cam2pad: np.ndarray, T_B_C: np.ndarray, pad_side_m: float, t: float,
                          epoch_s: float = 0.0) -> dict:
    """The ``LANDING_TARGET`` fields (keyword arguments of pymavlink's ``landing_target_encode``)."""
    from pymavlink.dialects.v20 import common as mav

    T_C_P = invert(cam2pad)
    p_C = T_C_P[:3, 3]  # pad centre in the camera frame
    T_B_P = np.asarray(T_B_C, np.float64) @ T_C_P
    p_FRD = FLU_TO_FRD @ T_B_P[:3, 3]
    R_FRD_P = FLU_TO_FRD @ T_B_P[:3, :3]
    qx, qy, qz, qw = quat_xyzw_from_matrix(R_FRD_P)
    rng = float(np.linalg.norm(p_C))
    size = 2.0 * math.atan2(pad_side_m / 2.0, max(rng, 1e-6))
    return {"time_usec": int(round((epoch_s + t) * 1e6)), "target_num": 0, "frame": mav.MAV_FRAME_BODY_FRD,
            "angle_x": math.atan2(p_C[0], p_C[2]), "angle_y": math.atan2(p_C[1], p_C[2]),
            "distance": float(np.linalg.norm(p_FRD)), "size_x": size, "size_y": size,
            "x": float(p_FRD[0]), "y": float(p_FRD[1]), "z": float(p_FRD[2]), "q": [qw, qx, qy, qz],
            "type": mav.LANDING_TARGET_TYPE_VISION_FIDUCIAL, "position_valid": 1}


class LandingTargetStream:
    """Encodes and sends ``LANDING_TARGET`` for each accepted estimate; a context manager."""

    def __init__(self, target: str, pad_side_m: float, T_B_C, epoch_s: float = 0.0,
                 system_id: int = 1, component_id: int = 197):  # 197: MAV_COMP_ID_VISUAL_INERTIAL_ODOMETRY
        from pymavlink.dialects.v20 import common as mav

        self.pad_side_m, self.T_B_C, self.epoch_s = float(pad_side_m), np.asarray(T_B_C, np.float64), float(epoch_s)
        self.mav = mav.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.sent = 0
        self._sock = self._file = None
        if target.startswith("udp:"):
            host, _, port = target[4:].rpartition(":")
            try:
                self._addr = (host or "127.0.0.1", int(port))
            except ValueError:
                raise InputError(f"--mavlink {target}: expected udp:HOST:PORT") from None
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        else:
            path = Path(target)
            if path.parent and not path.parent.is_dir():
                raise InputError(f"--mavlink {target}: folder {path.parent} does not exist")
            self._file = open(path, "wb")

    def send(self, est, seq_t: float | None = None) -> bool:
        """Send ``est`` if it is an accepted pose; returns whether a message went out."""
        if est.status != "ok" or est.cam2pad is None:
            return False
        t = est.t if seq_t is None else seq_t
        msg = self.mav.landing_target_encode(**landing_target_fields(est.cam2pad, self.T_B_C, self.pad_side_m, t,
                                                                     self.epoch_s))
        buf = msg.pack(self.mav)
        if self._sock is not None:
            self._sock.sendto(buf, self._addr)
        else:
            self._file.write(struct.pack(">Q", int(round((self.epoch_s + t) * 1e6))) + buf)
        self.sent += 1
        return True

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
        if self._file is not None:
            self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
