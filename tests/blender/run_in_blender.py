# SPDX-License-Identifier: GPL-3.0-or-later
"""Run tests/blender inside a Blender executable:

    $BLENDER --background --factory-startup --python tests/blender/run_in_blender.py -- [pytest args]

Blender's Python has no pytest, so the project's virtual environment (.venv, or $VENV)
lends its site-packages; the tests then drive the running Blender exactly as they drive
the bpy module. Exits with pytest's status.
"""
import glob
import os
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
venv = pathlib.Path(os.environ.get("VENV", ROOT / ".venv"))
for site in glob.glob(str(venv / "lib" / "python*" / "site-packages")):
    if site not in sys.path:
        sys.path.append(site)  # after Blender's own, so Blender's numpy wins
os.environ["KEYSTRAND_IN_BLENDER"] = "1"

import pytest  # noqa: E402

args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
code = pytest.main([str(ROOT / "tests" / "blender"), "--rootdir", str(ROOT), *args])
sys.exit(int(code))
