#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# One-time set-up on a fresh machine: the system libraries the bpy wheel and EGL need
# (only when missing, only as root), then a virtual environment with the pinned packages.
# Idempotent: a second run costs a second or two.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3

# Shared objects bpy links against and Mesa's EGL needs, with the Debian package that ships each.
declare -A LIBS=(
  [libEGL.so.1]=libegl1 [libGL.so.1]=libgl1 [libX11.so.6]=libx11-6 [libXrender.so.1]=libxrender1
  [libXi.so.6]=libxi6 [libxkbcommon.so.0]=libxkbcommon0 [libSM.so.6]=libsm6
  [libXfixes.so.3]=libxfixes3 [libXext.so.6]=libxext6 [libXxf86vm.so.1]=libxxf86vm1
  [libvulkan.so.1]=libvulkan1 [libGLX_mesa.so.0]=libglx-mesa0
)
missing=()
for lib in "${!LIBS[@]}"; do
  ldconfig -p 2>/dev/null | grep -q "$lib" || missing+=("${LIBS[$lib]}")
done
# Mesa's software drivers (llvmpipe) behind EGL.
compgen -G "/usr/lib/*/dri/swrast_dri.so" >/dev/null || compgen -G "/usr/lib/*/libgallium*.so" >/dev/null \
  || missing+=(libgl1-mesa-dri libegl-mesa0)
# A virtual X server, so the tracer's tests also run through GLX (the desktop Linux path).
command -v Xvfb >/dev/null 2>&1 || missing+=(xvfb)
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing system libraries: ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "setup: missing system libraries (${missing[*]}); install them with your package manager" >&2
  fi
fi

stamp="$VENV/.requirements.stamp"
if [ ! -x "$VENV/bin/python" ]; then
  "$PY" -m venv "$VENV"
fi
if [ ! -f "$stamp" ] || ! cmp -s requirements.txt "$stamp"; then
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -r requirements.txt
  cp requirements.txt "$stamp"
fi
