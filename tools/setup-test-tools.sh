#!/usr/bin/env bash
# Real clients the tests drive (the brief: "Real components in tests"), installed by `make test`.
# Each section installs only what is missing, so a second run is a no-op.  Run as root or with sudo.
set -euo pipefail
cd "$(dirname "$0")/.."
SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo

# --- Debian packages -------------------------------------------------------------------------
# xvfb/xauth: `piste view` under a virtual X server; xdotool: real X key/mouse events for it; nodejs/npm: the Khronos glTF validator;
# blender: headless re-import of piste's glTF export; chromium: the documentation site.
APT_PKGS="xvfb xauth xdotool chromium chromium-driver fonts-dejavu-core"
missing=""
for p in $APT_PKGS; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
command -v node >/dev/null 2>&1 || missing="$missing nodejs npm"
if [ -n "$missing" ]; then
  echo "installing test tools:$missing"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends $missing
fi

# --- npm tools (into .tools/, never global) --------------------------------------------------
