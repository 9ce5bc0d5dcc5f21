# SPDX-License-Identifier: GPL-3.0-or-later
"""Shader sources: the `.glsl` files of tracer/shaders, loaded by name, each program
compiled as `#version`, its compile-time switches, the header generated from
tracer/layout.py, then its files in order (GLSL has no include; the order is the
dependency order)."""
import pathlib

from . import layout

SHADER_DIR = pathlib.Path(__file__).resolve().parent / "shaders"


def load_shader(name):
    """The text of tracer/shaders/`name`."""
    return (SHADER_DIR / name).read_text()


def shader_source(version, files, defines=None):
    """One program's source: "#version `version` core", `defines` (name -> value) as
    #defines, layout.glsl_header(), then the files `files` in order."""
    head = f"#version {version} core\n" + "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return head + layout.glsl_header() + "".join(load_shader(f) for f in files)
