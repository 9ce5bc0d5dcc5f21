# SPDX-License-Identifier: GPL-3.0-or-later
"""The extension package: what the zip holds, that Blender's installer takes it, that
enabling is cheap, and that disabling leaves nothing behind."""
import os
import pathlib
import subprocess
import sys
import tomllib
import zipfile

import pytest
import bpy

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_zip_holds_the_extension_and_every_listed_wheel_but_no_tests(extension_zip):
    path, validator = extension_zip
    with open(ROOT / "blender_manifest.toml", "rb") as f:
        manifest = tomllib.load(f)
    assert path.name == f"{manifest['id']}-{manifest['version']}.zip"
    assert validator == "blender", "Blender's own manifest validator was not used"
    with zipfile.ZipFile(path) as z:
        names = set(z.namelist())
    assert {"blender_manifest.toml", "__init__.py", "addon/__init__.py", "addon/blender_curves.py"} <= names
    for wheel in manifest["wheels"]:
        assert wheel.removeprefix("./") in names
    platforms = " ".join(manifest["wheels"])
    for tag in ("manylinux", "win_amd64", "macosx_11_0_arm64"):
        assert f"moderngl-5.13.0-cp311-cp311-{tag}" in platforms
        assert f"glcontext-3.1.0-cp311-cp311-{tag}" in platforms
    assert not [n for n in names if n.startswith(("tests/", "benchmarks/")) or "__pycache__" in n]


def test_project_wheel_carries_the_pure_packages(extension_zip, tmp_path):
    path, _ = extension_zip
    with zipfile.ZipFile(path) as z:
        wheel = next(n for n in z.namelist() if n.startswith("wheels/keystrand_hair-"))
        z.extract(wheel, tmp_path)
    with zipfile.ZipFile(tmp_path / wheel) as w:
        names = set(w.namelist())
    for package in ("groom", "tracer", "hairio", "hairio/formats"):
        assert f"{package}/__init__.py" in names
    assert any(n.startswith("tracer/shaders/") for n in names), "the tracer's shaders are missing"
    assert any(n.endswith(".dist-info/RECORD") for n in names)


def test_own_schema_check_rejects_a_broken_manifest(builder, tmp_path):
    good = {"schema_version": "1.0.0", "id": "keystrand_hair", "version": "0.1.0", "name": "X",
            "tagline": "Hair", "maintainer": "M", "type": "add-on", "blender_version_min": "4.2.0",
            "license": ["SPDX:GPL-3.0-or-later"], "permissions": {"files": "Import and export hair files"}}
    builder.check_manifest(good, tmp_path)
    for broken, message in ((dict(good, id="key-strand"), "id"),
                            (dict(good, blender_version_min="4.2"), "blender_version_min"),
                            (dict(good, license=["GPL"]), "license"),
                            (dict(good, permissions={"files": ""}), "permissions"),
                            (dict(good, wheels=["./wheels/missing.whl"]), "wheels")):
        with pytest.raises(builder.BuildError, match=message):
            builder.check_manifest(broken, tmp_path)


def test_installer_unpacked_the_wheels_into_the_extensions_site_packages(extension):
    site = pathlib.Path(bpy.utils.user_resource('EXTENSIONS')) / ".local" / "lib" / \
        f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    for package in ("groom", "tracer", "hairio", "moderngl", "glcontext"):
        assert (site / package / "__init__.py").is_file() or (site / package).is_dir(), package
    assert pathlib.Path(extension.__file__).is_relative_to(pathlib.Path(os.environ["BLENDER_USER_RESOURCES"]))


def test_enabling_imports_nothing_heavy_and_the_wheels_do_the_work(extension_zip, tmp_path):
    """In a fresh process that cannot see this checkout: enabling loads none of groom, tracer
    or moderngl; Generate then runs on the copies Blender unpacked from the wheels."""
    code = f"""
import os, sys, bpy, bmesh
bpy.context.preferences.extensions.repos.new(name="t", module="t", custom_directory=os.path.join(os.environ["BLENDER_USER_RESOURCES"], "r"), source='USER')
assert bpy.ops.extensions.package_install_files(filepath={str(extension_zip[0])!r}, repo="t", enable_on_install=True) == {{'FINISHED'}}
assert hasattr(bpy.types.Object, "keystrand_hair")
print("HEAVY", sorted(m for m in ("groom", "tracer", "moderngl", "tracer.renderer") if m in sys.modules))
mesh = bpy.data.meshes.new("S"); bm = bmesh.new(); bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=0.1)
bm.to_mesh(mesh); bm.free()
obj = bpy.data.objects.new("S", mesh); bpy.context.scene.collection.objects.link(obj)
bpy.context.view_layer.objects.active = obj
assert bpy.ops.hair.load_preset(preset="wavy") == {{'FINISHED'}}
obj.keystrand_hair.count = 100
assert bpy.ops.hair.generate() == {{'FINISHED'}}
import groom
print("CURVES", len(obj.keystrand_hair.hair_object.data.curves))
# Large enough for worker processes: they run the wheel's groom too.
obj.keystrand_hair.count = 5000
assert bpy.ops.hair.generate() == {{'FINISHED'}}
from groom import parallel, processes
if processes.available() and parallel.cpu_threads() > 1:
    w = processes.workers(1)[0]
    w.send(eval, "__import__('groom').__file__")
    print("WORKER", processes.workers_cpu_seconds() > 0, w.receive())
print("GROOM", groom.__file__)
"""
    user = tmp_path / "user"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), PYTHONPATH="")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120,
                          cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "HEAVY []" in proc.stdout, proc.stdout
    assert "CURVES 100" in proc.stdout
    groom_file = proc.stdout.split("GROOM ")[1].strip()
    assert pathlib.Path(groom_file).is_relative_to(user / "extensions" / ".local"), groom_file
    if "WORKER " in proc.stdout:
        worked, worker_groom = proc.stdout.split("WORKER ")[1].split("\n")[0].split(" ", 1)
        assert worked == "True" and pathlib.Path(worker_groom).is_relative_to(user / "extensions" / ".local")


def test_disabling_leaves_no_class_handler_property_or_menu_entry(extension, ext_enable):
    enable, disable = ext_enable
    module_name = extension.__name__
    ours = lambda f: getattr(f, "__module__", "").startswith(module_name)  # noqa: E731
    assert hasattr(bpy.types, "HAIR_OT_generate") and hasattr(bpy.types.Object, "keystrand_hair")
    assert any(ours(f) for f in bpy.app.handlers.depsgraph_update_post)
    disable()
    try:
        leftovers = [name for name in dir(bpy.types) if name.startswith(("HAIR_OT_", "VIEW3D_PT_keystrand",
                                                                         "IMAGE_PT_keystrand"))]
        assert leftovers == []
        assert not hasattr(bpy.types.Object, "keystrand_hair")
        assert "HairSettings" not in dir(bpy.types)
        for name in dir(bpy.app.handlers):
            handlers = getattr(bpy.app.handlers, name)
            if isinstance(handlers, list):
                assert not [f for f in handlers if ours(f)], name
        assert not [f for f in bpy.types.TOPBAR_MT_file_export._dyn_ui_initialize() if ours(f)]
        assert not hasattr(bpy.ops.hair, "generate") or not _operator_exists("hair.generate")
    finally:
        enable()
    assert hasattr(bpy.types.Object, "keystrand_hair")


def _operator_exists(idname):
    try:
        getattr(bpy.ops.hair, idname.split(".")[1]).get_rna_type()
        return True
    except (KeyError, AttributeError):
        return False


@pytest.mark.skipif(not os.environ.get("BLENDER") or os.environ.get("KEYSTRAND_IN_BLENDER"),
                    reason="set BLENDER=/path/to/blender to run these tests inside a Blender executable too")
def test_the_same_tests_pass_inside_blender_background():
    runner = ROOT / "tests" / "blender" / "run_in_blender.py"
    proc = subprocess.run([os.environ["BLENDER"], "--background", "--factory-startup", "--python", str(runner),
                           "--", "-q", "-p", "no:cacheprovider"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-4000:]


class _Layout:
    """Records what a panel draws; rejects a property or operator that does not exist."""

    def __init__(self, seen):
        self.seen = seen
        self.use_property_split = False
        self.active = True

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, f"panel draws unknown setting {name!r}"
        self.seen.append(name)

    def operator(self, idname, **kwargs):
        module, name = idname.split(".")
        getattr(getattr(bpy.ops, module), name).get_rna_type()  # KeyError when missing
        self.seen.append(idname)
        return type("Props", (), {})()

    def label(self, **kwargs):
        pass

    def separator(self, **kwargs):
        pass

    def row(self, **kwargs):
        return self

    def column(self, **kwargs):
        return self


def test_panels_draw_every_setting_and_button(clean):
    from blender_scene import make_scalp
    scalp = make_scalp()
    seen = []
    context = bpy.context
    panels = [getattr(bpy.types, name) for name in dir(bpy.types)
              if name.startswith(("VIEW3D_PT_keystrand", "IMAGE_PT_keystrand"))]
    assert len(panels) >= 5
    for panel in panels:
        if panel.poll(context):
            fake = type("P", (), {"layout": _Layout(seen)})()
            if hasattr(panel, "draw_header"):
                panel.draw_header(fake, context)
            panel.draw(fake, context)
    settings = scalp.keystrand_hair.bl_rna.properties.keys()
    shown = set(seen)
    hidden = {"rna_type", "name", "role", "scalp", "hair_object", "use_key_color", "key_color", "key_radius",
              "key_group"}  # the key's own settings show only with a key active
    assert set(settings) - hidden - shown == set()
    for op in ("hair.generate", "hair.add_key_strand", "hair.render_preview", "hair.load_preset",
               "hair.save_preset", "hair.export"):
        assert op in shown
