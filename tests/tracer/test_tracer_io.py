# SPDX-License-Identifier: GPL-3.0-or-later
"""PNG writer, command line, worker process."""
import os
import shlex
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from hairio import InputError, Strands
from tracer import Camera, RenderSettings
from tracer.__main__ import main
from tracer.png import encode_png, linear_to_srgb, to_srgb8, write_png
from tracer.gl_state import context_backend
from tracer.worker import WorkerClient, WorkerError

from tracer_scenes import curls, uv_sphere


def _decode_png(data):
    """What encode_png wrote, decoded with every chunk's CRC checked."""
    from tracer.png import decode_png_rgba8
    return decode_png_rgba8(data)


def test_srgb_transfer_function():
    assert linear_to_srgb(0.5) == pytest.approx(0.7353569830524495)
    assert linear_to_srgb(0.002) == pytest.approx(12.92 * 0.002)
    assert linear_to_srgb(1.0) == pytest.approx(1.0) and linear_to_srgb(-1) == 0


def test_png_round_trip_unpremultiplies_alpha():
    img = np.zeros((3, 5, 4), np.float32)
    img[1, 2] = (0.25, 0.1, 0.0, 0.5)       # premultiplied: straight colour (0.5, 0.2, 0)
    out = _decode_png(encode_png(to_srgb8(img)))
    assert out.shape == (3, 5, 4)
    np.testing.assert_array_equal(out[1, 2], np.round([linear_to_srgb(0.5) * 255, linear_to_srgb(0.2) * 255, 0, 127.5]))
    assert out[0, 0, 3] == 0


def test_cli_renders_an_npz_and_prints_times(tmp_path, capsys):
    src = tmp_path / "tuft.npz"
    curls(6, 6).save_npz(src)
    out = tmp_path / "tuft.png"
    assert main(["render", str(src), "--out", str(out), "--size", "32x24", "--spp", "4", "--no-shadows"]) == 0
    img = _decode_png(out.read_bytes())
    assert img.shape == (24, 32, 4) and img[..., 3].max() > 0
    text = capsys.readouterr().out
    assert "upload" in text and "beams" in text and "render" in text


def test_cli_sampler_pixel_gives_the_coverage_one_pass_per_sample_gives(tmp_path, capsys):
    src = tmp_path / "tuft.npz"
    curls(6, 6).save_npz(src)
    images = {}
    for sampler in ("independent", "pixel"):
        out = tmp_path / f"{sampler}.png"
        assert main(["render", str(src), "--out", str(out), "--size", "32x24", "--spp", "16",
                     "--no-shadows", "--sampler", sampler]) == 0
        images[sampler] = _decode_png(out.read_bytes()).astype(float) / 255.0
    assert "sampler pixel" in capsys.readouterr().out
    a, b = images["independent"][..., 3], images["pixel"][..., 3]
    assert a.sum() > 10 and b.sum() > 10
    # The same samples decide each pixel's coverage (tests/tracer/test_tracer_pixel_sampler.py
    # holds the two samplers to each other in detail); an empty image misses by a.mean().
    assert abs(a.mean() - b.mean()) < 0.1 * a.mean()


@pytest.mark.parametrize("case", ["missing", "garbage", "nan", "size", "spp", "camera", "truncated-hair",
                                  "sampler-width"])
def test_cli_errors_exit_2_and_write_nothing(tmp_path, capsys, case):
    src = tmp_path / "in.npz"
    curls(3, 4).save_npz(src)
    args = ["render", str(src), "--out", str(tmp_path / "out.png")]
    if case == "missing":
        args[1] = str(tmp_path / "nope.npz")
    elif case == "garbage":
        src.write_bytes(b"not a zip at all")
    elif case == "nan":
        np.savez(src, points=np.array([[0, 0, 0], [np.nan, 0, 1.0]]), counts=np.array([2]))
    elif case == "size":
        args += ["--size", "big"]
    elif case == "spp":
        args += ["--spp", "3"]
    elif case == "camera":
        args += ["--camera", "1,2:3"]
    elif case == "sampler-width":
        args += ["--sampler", "pixel", "--spp", "16", "--min-pixel-width"]
    elif case == "truncated-hair":
        bad = tmp_path / "in.hair"
        bad.write_bytes(b"HAIR\x01\x00")
        src.unlink()
        args[1] = str(bad)
    assert main(args) == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "out.png").exists()
    assert not any(p.suffix == ".png" or p.name.startswith(".tmp-") for p in tmp_path.iterdir())


def _root():
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _kill(client):
    """Kill the worker and wait until it is gone (no guessed sleep)."""
    os.kill(client.pid, signal.SIGKILL)
    client._proc.wait(timeout=60)


def test_worker_renders_keeps_the_scene_and_restarts_after_a_crash():
    s = curls(6, 6)
    cam = Camera.look_at((0, -2.5, 0.5), (0, 0, 0.5), size=(24, 24))
    with WorkerClient(python=sys.executable, extra_sys_path=(_root(),), timeout=60) as client:
        client.set_strands(s)
        first = client.render(cam, RenderSettings())
        assert first.shape == (24, 24, 4) and first[..., 3].max() > 0
        sent = client.stats.bytes_uploaded
        client.render(cam.moved(position=(0.3, -2.5, 0.6)), RenderSettings())
        assert client.stats.bytes_uploaded == sent          # the scene stayed uploaded
        with pytest.raises(InputError):
            client.render(cam, RenderSettings(spp=2))           # bad input comes back as InputError
        _kill(client)
        with pytest.raises(WorkerError):
            client.render(cam, RenderSettings())
        np.testing.assert_array_equal(client.render(cam, RenderSettings()), first)   # fresh worker, same scene


def test_worker_imports_moderngl_from_where_this_process_does(tmp_path):
    # As in Blender, where moderngl lives in the extension's site-packages, which only the
    # parent put on sys.path: here the worker's interpreter runs without site-packages.
    python = tmp_path / "python-without-site"
    python.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} -S "$@"\n')
    python.chmod(0o755)
    alone = subprocess.run([str(python), "-c", "import moderngl"], capture_output=True, text=True, timeout=60)
    assert alone.returncode != 0 and "moderngl" in alone.stderr
    s = curls(4, 4)
    with WorkerClient(python=str(python), timeout=60) as client:
        client.set_strands(s)
        img = client.render(Camera.look_at((0, -2.5, 0.5), (0, 0, 0.5), size=(16, 16)), RenderSettings())
        assert img[..., 3].max() > 0
        assert client.stats.gl_backend == context_backend()      # the backend asked for here


def test_worker_is_given_the_backend_asked_for_here_even_with_its_own_environment(monkeypatch):
    env = {k: v for k, v in os.environ.items() if k != "KEYSTRAND_GL_BACKEND"}
    monkeypatch.setenv("KEYSTRAND_GL_BACKEND", "no-such-backend")
    with WorkerClient(env=env, timeout=60) as client:
        with pytest.raises(InputError, match="KEYSTRAND_GL_BACKEND='no-such-backend': expected one of"):
            client.set_strands(curls(2, 4))


def test_worker_that_hangs_times_out_with_a_clear_error(tmp_path):
    fake = tmp_path / "fake-python"
    fake.write_text("#!/bin/sh\nexec sleep 30\n")
    fake.chmod(0o755)
    client = WorkerClient(python=str(fake), timeout=1.0)
    t0 = time.perf_counter()
    with pytest.raises(WorkerError, match="no answer"):
        client.set_strands(Strands.empty())
    assert time.perf_counter() - t0 < 10
    client.close()


def test_worker_that_cannot_start_raises(tmp_path):
    fake = tmp_path / "broken-python"
    fake.write_text("#!/bin/sh\necho 'no such module' >&2\nexit 1\n")
    fake.chmod(0o755)
    client = WorkerClient(python=str(fake), timeout=10.0)
    with pytest.raises(WorkerError, match="died"):
        client.set_strands(Strands.empty())
    client.close()


def test_write_png_is_atomic(tmp_path):
    with pytest.raises(FileNotFoundError):
        write_png(tmp_path / "missing-folder" / "x.png", np.zeros((2, 2, 4)))


def test_every_render_option_has_help():
    from tracer.__main__ import build_parser
    sub = next(a for a in build_parser()._actions if a.dest == "command").choices["render"]
    missing = [a.dest for a in sub._actions if a.dest != "help" and not (a.help or "").strip()]
    assert missing == []


def test_worker_draws_meshes_and_keeps_them_across_a_restart():
    from tracer import Renderer
    s = curls(6, 6)
    meshes = [(*uv_sphere((0, -0.4, 0.5), 0.15), (0.1, 0.5, 0.9))]
    cam = Camera.look_at((0, -2.5, 0.5), (0, 0, 0.5), size=(24, 24))
    local = Renderer(build="numpy")
    local.set_strands(s)
    local.set_meshes(meshes)
    want = local.render(cam, RenderSettings())
    with WorkerClient(python=sys.executable, extra_sys_path=(_root(),), timeout=60) as client:
        client.set_strands(s)
        with pytest.raises(InputError, match="mesh 0: no faces"):
            client.set_meshes([(np.eye(3), np.zeros((0, 3), int), (1, 1, 1))])     # refused before it travels
        client.set_meshes(meshes)
        np.testing.assert_allclose(client.render(cam, RenderSettings()), want, atol=1e-6)
        _kill(client)
        with pytest.raises(WorkerError):
            client.render(cam, RenderSettings())
        np.testing.assert_allclose(client.render(cam, RenderSettings()), want, atol=1e-6)   # meshes re-sent


def test_worker_renders_while_the_caller_goes_on_and_answers_stay_in_order():
    s = curls(6, 6)
    cam = Camera.look_at((0, -2.5, 0.5), (0, 0, 0.5), size=(24, 24))
    moved = cam.moved(position=(0.3, -2.5, 0.6))
    with WorkerClient(python=sys.executable, extra_sys_path=(_root(),), timeout=60) as client:
        client.set_strands(s)
        want, want_moved = client.render(cam, RenderSettings()), client.render(moved, RenderSettings())
        client.render_begin(cam, RenderSettings())        # returns before the image is drawn
        deadline = time.monotonic() + 60
        while not client.render_ready() and time.monotonic() < deadline:
            time.sleep(0.01)
        np.testing.assert_array_equal(client.render_end(), want)
        # A call made while a render is owed gets its own answer, not the owed image.
        client.render_begin(cam, RenderSettings())
        np.testing.assert_array_equal(client.render(moved, RenderSettings()), want_moved)
        with pytest.raises(WorkerError, match="without a render_begin"):
            client.render_end()
        # Bad input comes back from render_end as it would from render.
        client.render_begin(cam, RenderSettings(spp=2))
        with pytest.raises(InputError):
            client.render_end()
        # The worker dies mid-render: render_ready says so and render_end raises.
        client.render_begin(cam, RenderSettings(spp=64))
        os.kill(client.pid, signal.SIGKILL)
        deadline = time.monotonic() + 10
        while not client.render_ready() and time.monotonic() < deadline:
            time.sleep(0.01)
        assert client.render_ready()
        with pytest.raises(WorkerError):
            client.render_end()
        np.testing.assert_array_equal(client.render(cam, RenderSettings()), want)   # fresh worker, same scene
