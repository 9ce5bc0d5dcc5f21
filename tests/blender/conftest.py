# SPDX-License-Identifier: GPL-3.0-or-later
"""The extension under test: built once per session, installed with Blender's own
extension installer into a throw-away user folder, enabled, and driven through bpy.ops.

Blender reads BLENDER_USER_RESOURCES each time it looks up a user folder, so pointing it
at a temporary directory keeps the user's own preferences and extensions untouched; the
test repository is a custom-directory user repository removed at the end.
"""
import atexit
import importlib
import importlib.util
import os
import pathlib
import shutil
import sys
import tempfile

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
_USER = tempfile.mkdtemp(prefix="keystrand-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = _USER
# The preview renders in-process unless a test asks for the worker: a background test
# process has no use for the isolation, and starting a worker costs a second.
os.environ.setdefault("KEYSTRAND_PREVIEW_IN_PROCESS", "1")

import bpy  # noqa: E402  (after the environment is set)

from blender_scene import clear_scene  # noqa: E402

REPO_MODULE = "keystrand_test"
EXT_ID = "keystrand_hair"
EXT_MODULE = f"bl_ext.{REPO_MODULE}.{EXT_ID}"


def _load_builder():
    spec = importlib.util.spec_from_file_location("build_extension", ROOT / "scripts" / "build_extension.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def builder():
    return _load_builder()


@pytest.fixture(scope="session")
def extension_zip(builder, tmp_path_factory):
    """(zip path, validator used): built once for the whole session."""
    out = tmp_path_factory.mktemp("dist")
    path, validator = builder.build(out)
    return path, validator


def _enable():
    import addon_utils
    addon_utils.enable(EXT_MODULE, default_set=True, handle_error=None)


def _disable():
    import addon_utils
    addon_utils.disable(EXT_MODULE, default_set=True, handle_error=None)


@pytest.fixture(scope="session")
def extension(extension_zip):
    """The installed and enabled extension's package module."""
    path, _ = extension_zip
    repo_dir = pathlib.Path(_USER) / "test_repo"
    repos = bpy.context.preferences.extensions.repos
    repo = repos.new(name="Key-strand test", module=REPO_MODULE, custom_directory=str(repo_dir), source='USER')
    try:
        result = bpy.ops.extensions.package_install_files(filepath=str(path), repo=REPO_MODULE,
                                                          enable_on_install=True)
        assert result == {'FINISHED'}, result
        assert EXT_MODULE in bpy.context.preferences.addons, "the installer did not enable the extension"
        yield importlib.import_module(EXT_MODULE)
    finally:
        if EXT_MODULE in bpy.context.preferences.addons:
            _disable()
        for r in [r for r in repos if r.module == REPO_MODULE]:
            repos.remove(r)
        shutil.rmtree(_USER, ignore_errors=True)


@pytest.fixture(scope="session")
def ext_enable():
    return _enable, _disable


@pytest.fixture()
def clean(extension):
    """An empty scene (objects, data and images from earlier tests removed)."""
    clear_scene()
    bpy.context.scene.camera = None
    yield extension
    clear_scene()
    # Drop cached generators so nothing of this test outlives it.
    importlib.import_module(f"{extension.__name__}.addon.live").forget_all()


# bpy 4.2 as a Python module shuts Blender down (WM_exit) only when the bpy module object is
# freed at interpreter exit; once an extension repository has been removed in the process
# (the `extension` fixture's clean-up) something keeps a reference to it, so that never
# happens, and C++ static destructors free Blender's space types after Python is gone. Their
# Python-defined panels then take the GIL of a finished interpreter: a segfault (exit 139)
# after every run, passed or failed. Seen with 4.2.23; 5.0.1 and 5.3.0 shut down cleanly.
# For those Blenders the process ends with pytest's own status as soon as pytest is done.
_EXIT_BEFORE_TEARDOWN = bpy.app.version < (4, 3, 0) and not os.environ.get("KEYSTRAND_IN_BLENDER")
_exit_status = None


def pytest_sessionfinish(session, exitstatus):
    global _exit_status
    _exit_status = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if _EXIT_BEFORE_TEARDOWN and _exit_status is not None:
        atexit._run_exitfuncs()  # pytest's own clean-up (temporary folders' locks) still runs
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_exit_status)
