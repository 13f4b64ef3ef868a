#!/usr/bin/env bash
# Install everything hvloc needs on a fresh Debian machine; safe to run again (idempotent).
#   system: libosmesa6 (headless OpenGL for pyrender), via apt-get when missing
#   python: a virtual environment in $VENV (default .venv) with torch (CPU) and hvloc[test]
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}

if ! ldconfig -p 2>/dev/null | grep -q 'libOSMesa\.so'; then
  echo "[bootstrap] installing libosmesa6 (headless OpenGL)"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libosmesa6 >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[bootstrap] creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
stamp="$VENV/.hvloc-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "[bootstrap] installing Python packages into $VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip 2>&1 | grep -v 'is ignored' || true
  # The CPU build of torch lies on this machine's disk; asking for it first keeps pip from
  # pulling a multi-GB CUDA build for kornia's dependency.
  "$VENV/bin/python" -m pip install -q "torch==2.13.0" 2>&1 | grep -v 'is ignored' || true
  "$VENV/bin/python" -m pip install -q -e ".[test]" 2>&1 | grep -v 'is ignored' || true
  "$VENV/bin/python" -c "import torch, kornia, cv2, pyrender, trimesh, pydantic" \
    || { echo "[bootstrap] Python packages failed to install" >&2; exit 1; }
  touch "$stamp"
fi
