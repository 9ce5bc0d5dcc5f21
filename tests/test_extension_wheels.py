# SPDX-License-Identifier: GPL-3.0-or-later
"""The manifest's wheels cover every platform it names for every Python the Blender versions
it claims embed: Blender's installer derives the supported Python versions from the wheel
names and refuses an extension with none for its own (Blender 5.1+ embeds Python 3.13)."""
import pathlib
import tomllib

import pytest
from packaging.utils import parse_wheel_filename

ROOT = pathlib.Path(__file__).resolve().parents[1]
# The Python each Blender line embeds, from 4.2 LTS (the manifest's minimum) to the current one.
BLENDER_PYTHONS = {"4.2": "311", "4.5": "311", "5.0": "311", "5.1": "313", "5.2": "313", "5.3": "313"}
# Manifest platform -> the platform-tag prefix its wheels carry.
PLATFORM_TAGS = {"linux-x64": ("manylinux", "x86_64"), "windows-x64": ("win_amd64", ""),
                 "macos-arm64": ("macosx_", "arm64"), "macos-x64": ("macosx_", "x86_64")}
COMPILED = ("moderngl", "glcontext", "alembic3d")


def _manifest():
    with open(ROOT / "blender_manifest.toml", "rb") as f:
        return tomllib.load(f)


def _wheel_tags():
    found = []
    for wheel in _manifest()["wheels"]:
        name, _version, _build, tags = parse_wheel_filename(pathlib.Path(wheel).name)
        found.append((str(name), {(t.interpreter, t.abi, t.platform) for t in tags}))
    return found


def _covers(tags, python, platform):
    prefix, arch = PLATFORM_TAGS[platform]
    return any(interp in ("py3", f"cp{python}") and abi in ("none", f"cp{python}", "abi3")
               and plat.startswith(prefix) and plat.endswith(arch) or
               (interp == "py3" and abi == "none" and plat == "any")
               for interp, abi, plat in tags)


@pytest.mark.parametrize("blender", sorted(BLENDER_PYTHONS))
def test_every_platform_has_each_compiled_wheel_for_the_python_of_each_blender(blender):
    manifest = _manifest()
    python = BLENDER_PYTHONS[blender]
    wheels = _wheel_tags()
    for platform in manifest["platforms"]:
        for package in COMPILED:
            matching = [tags for name, tags in wheels if name == package and _covers(tags, python, platform)]
            assert len(matching) == 1, (f"Blender {blender} (Python {python[0]}.{python[1:]}) on {platform}: "
                                        f"{len(matching)} {package} wheels in the manifest, expected 1")


def test_no_wheel_is_for_a_platform_or_python_the_manifest_does_not_claim():
    manifest = _manifest()
    pythons = set(BLENDER_PYTHONS.values())
    for name, tags in _wheel_tags():
        if name == "keystrand-hair":
            continue
        assert any(_covers(tags, py, plat) for py in pythons for plat in manifest["platforms"]), \
            f"{name} {sorted(tags)} serves no (Python, platform) the manifest claims"


def test_the_project_wheel_is_pure_python():
    (tags,) = [t for name, t in _wheel_tags() if name == "keystrand-hair"]
    assert tags == {("py3", "none", "any")}
