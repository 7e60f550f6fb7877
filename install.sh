#!/usr/bin/env bash
# Installs twin and everything it needs on a fresh Debian/Ubuntu machine with Python >= 3.10.
set -euo pipefail
cd "$(dirname "$0")"
# System libraries: Open3D needs libusb and OpenGL/GOMP runtime libraries.
if command -v apt-get >/dev/null 2>&1; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq libusb-1.0-0 libgl1 libgomp1 >/dev/null
fi
python3 -m pip install -q -e ".[test]"
