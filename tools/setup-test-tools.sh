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

# --- glTF export tests (issue 13): Blender (headless re-import) and the Khronos glTF validator ---
# blender: Debian 12's 3.4 (~30 s, 174 packages, 23 MB download); its glTF importer needs numpy in
# the system Python (python3-numpy).  gltf-validator: npm package into .tools/, run by
# tools/gltf_validate.mjs.
GLTF_APT=""
command -v blender >/dev/null 2>&1 || GLTF_APT="$GLTF_APT blender"
dpkg -s python3-numpy >/dev/null 2>&1 || GLTF_APT="$GLTF_APT python3-numpy"  # Blender's Python (Debian's), not the venv
if [ -n "$GLTF_APT" ]; then
  echo "installing glTF test tools:$GLTF_APT"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends $GLTF_APT
fi
if [ ! -f .tools/node_modules/gltf-validator/package.json ]; then
  mkdir -p .tools
  npm install --prefix .tools --no-audit --no-fund --loglevel=error gltf-validator@2.0.0-dev.3.10
fi
