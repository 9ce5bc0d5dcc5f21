# SPDX-License-Identifier: GPL-3.0-or-later
"""Build the Blender extension zip: dist/<id>-<version>.zip.

    python scripts/build_extension.py --out dist

1. Fetch the platform wheels the manifest lists (moderngl, glcontext, alembic3d) into build/wheels/,
   once; later builds reuse them and need no network.
2. Build this project's own pure-Python wheel (groom, tracer, hairio; the packages
   pyproject.toml lists), so Blender installs them into its extensions' site-packages.
3. Stage only what the extension ships (root __init__.py, manifest, addon/, presets/,
   wheels/) and hand it to Blender's own extension builder, which validates the manifest
   and writes the zip; then validate the zip again with Blender's validator.

Blender's builder is the `blender_ext.py` command line that ships inside Blender (and the
bpy module) under scripts/addons_core/bl_pkg/cli/. Where it cannot be found, a smaller
schema check of our own runs and the zip is written with zipfile.
"""
import argparse
import glob
import importlib.util
import os
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
import zipfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
WHEEL_CACHE = ROOT / "build" / "wheels"
SHIPPED = ("__init__.py", "blender_manifest.toml", "addon", "presets")
# pip --platform tags to try for each manifest platform (wheels carry several compatible tags).
PIP_PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64",
                  "manylinux_2_5_x86_64", "manylinux1_x86_64"],
    "windows-x64": ["win_amd64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64"],
    "macos-x64": ["macosx_10_9_x86_64", "macosx_10_13_x86_64", "macosx_11_0_x86_64"],
}
REQUIRED_KEYS = {"schema_version": str, "id": str, "version": str, "name": str, "tagline": str,
                 "maintainer": str, "type": str, "blender_version_min": str, "license": list}


class BuildError(Exception):
    pass


def read_manifest(path):
    with open(path, "rb") as f:
        return tomllib.load(f)


def check_manifest(manifest, source_dir):
    """Our own schema check, used only where Blender's validator is unavailable."""
    problems = []
    for key, kind in REQUIRED_KEYS.items():
        if not isinstance(manifest.get(key), kind):
            problems.append(f"{key}: missing or not a {kind.__name__}")
    if manifest.get("schema_version") != "1.0.0":
        problems.append("schema_version: must be \"1.0.0\"")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", str(manifest.get("id", ""))):
        problems.append("id: must be a Python identifier")
    version_re = r"\d+\.\d+\.\d+"
    for key in ("version", "blender_version_min"):
        if not re.fullmatch(version_re, str(manifest.get(key, ""))):
            problems.append(f"{key}: must be MAJOR.MINOR.PATCH")
    if not all(str(x).startswith("SPDX:") for x in manifest.get("license", [])):
        problems.append("license: entries must start with \"SPDX:\"")
    if manifest.get("type") != "add-on":
        problems.append("type: must be \"add-on\"")
    tagline = str(manifest.get("tagline", ""))
    if len(tagline) > 64 or tagline.endswith((".", "!", "?")):
        problems.append("tagline: at most 64 characters, no final punctuation")
    for wheel in manifest.get("wheels", []):
        if not (source_dir / wheel).is_file():
            problems.append(f"wheels: {wheel} not found in the staged package")
    for key, reason in manifest.get("permissions", {}).items():
        if key not in ("files", "network", "clipboard", "camera", "microphone"):
            problems.append(f"permissions: unknown permission {key!r}")
        if not reason or str(reason).endswith("."):
            problems.append(f"permissions.{key}: give a reason without a final full stop")
    if problems:
        raise BuildError("blender_manifest.toml is invalid:\n  " + "\n  ".join(problems))


def blender_ext_cli():
    """Path of Blender's `blender_ext.py`, found beside the bpy module, or None."""
    if env := os.environ.get("BLENDER_EXT_CLI"):
        return pathlib.Path(env)
    spec = importlib.util.find_spec("bpy")
    roots = []
    if spec and spec.origin:
        roots.append(pathlib.Path(spec.origin).parent)
    if blender := os.environ.get("BLENDER"):
        roots.append(pathlib.Path(blender).resolve().parent)
    for root in roots:
        hits = sorted(glob.glob(str(root / "*" / "scripts" / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py")))
        if hits:
            return pathlib.Path(hits[-1])
    return None


def run_checked(cmd, what):
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise BuildError(f"{what} failed (exit {proc.returncode}):\n{proc.stdout}{proc.stderr}")
    return proc.stdout


def fetch_platform_wheels(manifest, offline):
    """Download every listed third-party wheel that is not yet in build/wheels/."""
    wanted = [pathlib.Path(w).name for w in manifest.get("wheels", [])]
    project = project_wheel_name()
    missing = [w for w in wanted if w != project and not (WHEEL_CACHE / w).is_file()]
    if not missing:
        return
    if offline:
        raise BuildError(f"wheels missing from {WHEEL_CACHE} and --offline given: {missing}")
    WHEEL_CACHE.mkdir(parents=True, exist_ok=True)
    for name in missing:
        # name-version-pyXY-abi-platform.whl: ask pip for exactly that distribution.
        dist, version, pytag = name.split("-")[:3]
        platform_of = next((p for p, tags in PIP_PLATFORMS.items()
                            if any(t in name for t in tags)), None)
        if platform_of is None:
            raise BuildError(f"wheels: cannot tell the platform of {name}")
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--only-binary=:all:",
               "--no-deps", "--python-version", pytag.removeprefix("cp")[:1] + "." + pytag.removeprefix("cp")[1:],
               "--implementation", "cp", "-d", str(WHEEL_CACHE), f"{dist}=={version}"]
        for tag in PIP_PLATFORMS[platform_of]:
            cmd += ["--platform", tag]
        run_checked(cmd, f"pip download {name}")
        if not (WHEEL_CACHE / name).is_file():
            raise BuildError(f"pip download did not produce {name}; the manifest's wheel name is out of date")


def project_wheel_name():
    with open(ROOT / "pyproject.toml", "rb") as f:
        project = tomllib.load(f)["project"]
    return f"{project['name'].replace('-', '_')}-{project['version']}-py3-none-any.whl"


def build_project_wheel(dest):
    """This project's pure-Python wheel (PEP 427) written directly with zipfile; returns its path.

    The packages are pure Python plus data files, so a wheel is a zip of them with a
    dist-info folder. Writing it here needs neither network nor the `wheel` package, which
    `pip wheel . --no-build-isolation` would need in the environment.
    """
    import base64
    import hashlib
    with open(ROOT / "pyproject.toml", "rb") as f:
        pyproject = tomllib.load(f)
    project = pyproject["project"]
    setup = pyproject["tool"]["setuptools"]
    packages = setup["packages"]
    dist = project["name"].replace("-", "_")
    info = f"{dist}-{project['version']}.dist-info"
    path = pathlib.Path(dest) / project_wheel_name()
    files = {}
    # The same selection setuptools makes: each listed package's modules, read from its
    # package-dir mapping if it has one, plus its package-data patterns.
    for package in packages:
        source = ROOT / setup.get("package-dir", {}).get(package, package.replace(".", "/"))
        target = package.replace(".", "/")
        patterns = ["*.py", *setup.get("package-data", {}).get(package, [])]
        for pattern in patterns:
            for file in sorted(source.glob(pattern)):
                if file.is_file():
                    files[f"{target}/{file.relative_to(source).as_posix()}"] = file.read_bytes()
    if not any(name.endswith("/__init__.py") for name in files):
        raise BuildError(f"project wheel: none of the packages {packages} has an __init__.py")
    requires = "".join(f"Requires-Dist: {d}\n" for d in project.get("dependencies", []))
    files[f"{info}/METADATA"] = (f"Metadata-Version: 2.1\nName: {project['name']}\n"
                                 f"Version: {project['version']}\nSummary: {project.get('description', '')}\n"
                                 f"License: GPL-3.0-or-later\n{requires}").encode()
    files[f"{info}/WHEEL"] = (b"Wheel-Version: 1.0\nGenerator: keystrand build_extension\n"
                              b"Root-Is-Purelib: true\nTag: py3-none-any\n")
    files[f"{info}/top_level.txt"] = "".join(sorted({p.split(".")[0] + "\n" for p in packages})).encode()
    record = []
    for name, data in files.items():
        digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
        record.append(f"{name},sha256={digest},{len(data)}")
    record.append(f"{info}/RECORD,,")
    files[f"{info}/RECORD"] = ("\n".join(record) + "\n").encode()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in files.items():
            # A fixed timestamp keeps the wheel byte-identical for identical sources.
            z.writestr(zipfile.ZipInfo(name, date_time=(2024, 1, 1, 0, 0, 0)), data, zipfile.ZIP_DEFLATED)
    return path


def stage(manifest, stage_dir):
    stage_dir.mkdir(parents=True)
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in SHIPPED:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, stage_dir / name, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, stage_dir / name)
        else:
            raise BuildError(f"{name}: missing from the repository")
    wheels_dir = stage_dir / "wheels"
    wheels_dir.mkdir()
    built = build_project_wheel(wheels_dir)
    expected = project_wheel_name()
    if built.name != expected:
        raise BuildError(f"wheels: built {built.name} but the manifest expects {expected}; "
                         "update blender_manifest.toml to the pyproject version")
    for wheel in manifest.get("wheels", []):
        name = pathlib.Path(wheel).name
        if name != expected:
            shutil.copy2(WHEEL_CACHE / name, wheels_dir / name)


def zip_ourselves(stage_dir, out_zip, manifest):
    check_manifest(manifest, stage_dir)
    with zipfile.ZipFile(out_zip, "w", zipfile.ZIP_DEFLATED) as z:
        for path in sorted(stage_dir.rglob("*")):
            if path.is_file():
                z.write(path, path.relative_to(stage_dir).as_posix())


def build(out_dir, offline=False, use_blender=True):
    """Build and validate the zip; returns its path."""
    manifest = read_manifest(ROOT / "blender_manifest.toml")
    listed = [pathlib.Path(w).name for w in manifest.get("wheels", [])]
    if project_wheel_name() not in listed:
        raise BuildError(f"wheels: the manifest must list ./wheels/{project_wheel_name()}")
    fetch_platform_wheels(manifest, offline)
    out_dir = pathlib.Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    out_zip = out_dir / f"{manifest['id']}-{manifest['version']}.zip"
    cli = blender_ext_cli() if use_blender else None
    with tempfile.TemporaryDirectory() as tmp:
        stage_dir = pathlib.Path(tmp) / manifest["id"]
        stage(manifest, stage_dir)
        partial = out_dir / (out_zip.name + ".part")
        if cli is not None:
            # Blender's own builder validates the manifest (schema, tags, wheels, permissions).
            run_checked([sys.executable, str(cli), "build", "--source-dir", str(stage_dir),
                         "--output-filepath", str(partial)], "Blender's extension build")
        else:
            zip_ourselves(stage_dir, partial, manifest)
    if cli is not None:
        run_checked([sys.executable, str(cli), "validate", str(partial)], "Blender's extension validate")
    with zipfile.ZipFile(partial) as z:
        names = z.namelist()
    leaked = [n for n in names if n.startswith(("tests/", "benchmarks/")) or "__pycache__" in n]
    if leaked:
        partial.unlink()
        raise BuildError(f"the zip holds files it must not ship: {leaked[:5]}")
    os.replace(partial, out_zip)
    return out_zip, ("blender" if cli is not None else "own")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default="dist", help="output folder (default: dist)")
    ap.add_argument("--offline", action="store_true", help="never download; use build/wheels/ only")
    ap.add_argument("--no-blender-validator", action="store_true",
                    help="use the built-in schema check even when Blender's validator is available")
    args = ap.parse_args(argv)
    try:
        path, validator = build(args.out, offline=args.offline, use_blender=not args.no_blender_validator)
    except BuildError as e:
        print(f"build_extension: {e}", file=sys.stderr)
        return 2
    print(f"build_extension: wrote {path} (manifest validated by {validator} validator)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
