#!/usr/bin/env bash
# SPDX-License-Identifier: GPL-3.0-or-later
# The Blender test matrix beside the main environment (.venv, Blender 5.0.1 on Python 3.11):
#   .venv-bpy42  Blender 4.2 LTS as a module, Python 3.11   (requirements/blender-4.2.txt)
#   .venv-bpy53  Blender 5.3 as a module,     Python 3.13   (requirements/blender-5.3.txt)
# Blender 5.1 and later embed Python 3.13, which Debian 12 does not package: the interpreter
# is looked for on PATH, then under pyenv, then installed from the system packages where
# they have it. Says what it found or did; idempotent (a second run costs a second).
set -euo pipefail
cd "$(dirname "$0")/.."

find_python() {   # find_python 3.13 -> path of an interpreter of that version, or nothing
  local want=$1 cand root
  for cand in "python$want" "/usr/local/bin/python$want" "/usr/bin/python$want"; do
    # A pyenv shim is on PATH whether or not its version is selected: ask it to run.
    if command -v "$cand" >/dev/null 2>&1 && "$cand" -c '' >/dev/null 2>&1; then
      command -v "$cand"; return
    fi
  done
  root=$( (command -v pyenv >/dev/null 2>&1 && pyenv root) || echo "${PYENV_ROOT:-$HOME/.pyenv}")
  for cand in $(ls -d "$root"/versions/"$want".* 2>/dev/null | sort -V -r); do
    if [ -x "$cand/bin/python$want" ]; then echo "$cand/bin/python$want"; return; fi
  done
}

python_for() {   # python_for 3.13 -> an interpreter, installing one from apt when possible
  local want=$1 py
  py=$(find_python "$want")
  if [ -z "$py" ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    apt-get update -qq >/dev/null 2>&1 || true
    if apt-cache show "python$want-venv" >/dev/null 2>&1; then
      echo "setup-blender: installing python$want from the system packages" >&2
      DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        "python$want" "python$want-venv" >/dev/null
      py=$(find_python "$want")
    fi
  fi
  if [ -z "$py" ]; then
    echo "setup-blender: no Python $want found (PATH, pyenv) and none in the system packages;" \
         "install Python $want (e.g. 'pyenv install $want') and run again" >&2
    return 1
  fi
  echo "$py"
}

make_env() {   # make_env VENV PYTHON_VERSION REQUIREMENTS
  local venv=$1 want=$2 reqs=$3 py stamp
  stamp="$venv/.requirements.stamp"
  if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && cmp -s "$reqs" "$stamp"; then
    return
  fi
  if [ ! -x "$venv/bin/python" ]; then
    py=$(python_for "$want")
    echo "setup-blender: $venv from $py ($("$py" --version 2>&1)) for $reqs"
    "$py" -m venv "$venv"
  fi
  "$venv/bin/python" -m pip install -q --upgrade pip
  "$venv/bin/python" -m pip install -q -r "$reqs"
  cp "$reqs" "$stamp"
}

make_env .venv-bpy42 3.11 requirements/blender-4.2.txt
make_env .venv-bpy53 3.13 requirements/blender-5.3.txt
