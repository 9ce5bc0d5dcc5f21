# SPDX-License-Identifier: GPL-3.0-or-later
"""An out-of-process renderer: Blender talks to it, so a GL or driver crash never takes
Blender down and Blender's own GL context is never touched.

`python -m tracer.worker` reads requests from stdin and answers on stdout, each message an
8-byte little-endian length followed by a pickle: a request is (command, args), an answer is
("ok", value) or ("error", kind, message). Commands: set_strands, update_strands,
set_meshes, render, stats, quit. Only the parent that spawned the worker writes to its stdin; pickle is used
because both ends are this package.
"""
import dataclasses
import os
import queue
import subprocess
import sys
import threading

from hairio import pipes
from hairio.pipes import read_message, write_message

# Packages the worker imports that may live elsewhere than the tracer: in Blender the
# extension's wheels are in its own site-packages, which only the parent has on sys.path.
_PACKAGES = ("numpy", "moderngl", "glcontext")
# Their folders reach the worker here and go at the end of its sys.path, as in the parent,
# before the tracer package (which imports numpy) loads: on PYTHONPATH a whole
# site-packages would come before the standard library.
_APPEND_ENV = "KEYSTRAND_WORKER_APPEND_PATH"
_BOOT = ("import os, sys\n"
         f"for p in os.environ.get({_APPEND_ENV!r}, '').split(os.pathsep):\n"
         "    if p and p not in sys.path:\n"
         "        sys.path.append(p)\n"
         "from tracer.worker import main\n"
         "main()\n")
_PASSED_ENV = ("KEYSTRAND_GL_BACKEND",)


def package_paths():
    """The folders numpy, moderngl and glcontext import from in this process, each once."""
    return pipes.package_paths(_PACKAGES)


class WorkerError(RuntimeError):
    """The worker died, timed out or failed; the next call starts a fresh one."""


def serve(inp, out):
    """The worker's loop: one Renderer, the scene kept between requests."""
    from hairio import InputError
    from .renderer import Renderer
    renderer = None
    while True:
        try:
            command, args = read_message(inp)
        except EOFError:
            return
        if command == "quit":
            write_message(out, ("ok", None))
            return
        try:
            if renderer is None:
                renderer = Renderer()
            if command == "set_strands":
                value = renderer.set_strands(*args)
            elif command == "update_strands":
                value = renderer.update_strands(*args)
            elif command == "set_meshes":
                value = renderer.set_meshes(*args)
            elif command == "render":
                value = renderer.render(*args)
            elif command == "stats":
                value = dataclasses.replace(renderer.stats)     # a copy: tracer.stats.RenderStats
            else:
                raise ValueError(f"unknown command {command!r}")
            write_message(out, ("ok", value))
        except InputError as e:
            write_message(out, ("error", "InputError", str(e)))
        except Exception as e:  # report, keep serving: the scene may still be good
            write_message(out, ("error", type(e).__name__, str(e)))


class WorkerClient:
    """Same API as Renderer (set_strands, update_strands, set_meshes, render, stats, close),
    served by a child process. Any death or time-out raises WorkerError and the next call
    restarts the worker (re-sending the last strands and meshes so a render still has its
    scene)."""

    def __init__(self, python=sys.executable, extra_sys_path=(), timeout=120.0, env=None):
        self.python = python
        self.extra_sys_path = tuple(extra_sys_path)
        self.timeout = timeout
        self.env = env
        self._proc = None
        self._answers = None
        self._strands = None
        self._meshes = None
        self._pending = None       # the command whose answer render_end still collects

    # --- process management -----------------------------------------------------------
    def _start(self):
        env = dict(os.environ if self.env is None else self.env)
        for name in _PASSED_ENV:    # the worker's context is made by the backend asked for here
            if name in os.environ:
                env.setdefault(name, os.environ[name])
        package_root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        paths = [package_root, *self.extra_sys_path]
        if env.get("PYTHONPATH"):
            paths.append(env["PYTHONPATH"])
        env["PYTHONPATH"] = os.pathsep.join(paths)
        env[_APPEND_ENV] = os.pathsep.join(package_paths())
        self._proc = subprocess.Popen([self.python, "-c", _BOOT], stdin=subprocess.PIPE,
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        self._answers = queue.Queue()
        self._stderr = []
        proc, answers = self._proc, self._answers

        def pump():   # a reader thread, so a silent worker cannot block the caller forever
            try:
                while True:
                    answers.put(read_message(proc.stdout))
            except Exception as e:
                answers.put(("dead", str(e)))

        def drain():
            for line in proc.stderr:
                self._stderr.append(line.decode(errors="replace"))
                del self._stderr[:-20]

        threading.Thread(target=pump, daemon=True).start()
        threading.Thread(target=drain, daemon=True).start()

    def _kill(self):
        proc, self._proc = self._proc, None
        self._pending = None       # its answer died with it
        if proc is not None and proc.poll() is None:
            proc.kill()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass

    def _call(self, command, *args, timeout=None):
        self._send(command, args, timeout)
        return self._receive(command, timeout)

    def _send(self, command, args, timeout):
        """Write a request, starting the worker (and giving it its scene) when there is none;
        an answer still owed for a render_begin is collected and dropped first, so every
        answer goes to the request it belongs to."""
        if self._pending is not None:
            pending, self._pending = self._pending, None
            try:
                self._receive(pending, timeout)
            except Exception:
                pass   # the request that follows meets the same failure, and reports it
        if self._proc is not None and self._proc.poll() is not None:
            code = self._proc.returncode
            self._kill()
            raise WorkerError(f"tracer worker exited (code {code}) since the last call; "
                              f"its last words: {''.join(self._stderr[-5:]).strip()!r}. "
                              "The next call starts a fresh one")
        if self._proc is None:
            self._start()
            if command not in ("set_strands", "quit") and self._strands is not None:
                self._exchange("set_strands", (self._strands,), timeout)
            if command not in ("set_meshes", "quit") and self._meshes is not None:
                self._exchange("set_meshes", (self._meshes,), timeout)
        self._write(command, args)

    def _write(self, command, args):
        try:
            write_message(self._proc.stdin, (command, args))
        except (BrokenPipeError, OSError) as e:
            self._kill()
            raise WorkerError(f"tracer worker died before {command!r} ({e}); "
                              f"its last words: {''.join(self._stderr[-5:]).strip()!r}") from None

    def _exchange(self, command, args, timeout):
        self._write(command, args)
        return self._receive(command, timeout)

    def _receive(self, command, timeout):
        try:
            answer = self._answers.get(timeout=self.timeout if timeout is None else timeout)
        except queue.Empty:
            self._kill()
            raise WorkerError(f"tracer worker: no answer to {command!r} within "
                              f"{self.timeout if timeout is None else timeout:.0f} s; it was stopped "
                              "and will restart on the next call") from None
        if answer[0] == "ok":
            return answer[1]
        if answer[0] == "dead":
            self._kill()
            raise WorkerError(f"tracer worker died during {command!r}; "
                              f"its last words: {''.join(self._stderr[-5:]).strip()!r}")
        _, kind, message = answer
        if kind == "InputError":
            from hairio import InputError
            raise InputError(message)
        raise WorkerError(f"tracer worker: {kind}: {message}")

    # --- the Renderer API -------------------------------------------------------------
    def set_strands(self, strands):
        self._strands = strands
        return self._call("set_strands", strands)

    def set_meshes(self, meshes):
        """As Renderer.set_meshes; the meshes are checked here, before they travel."""
        from .meshes import mesh_set
        self._meshes = mesh_set(meshes)
        return self._call("set_meshes", self._meshes)

    def update_strands(self, strand_ids, strands):
        self._strands = strands
        return self._call("update_strands", strand_ids, strands)

    def render(self, camera, settings=None):
        return self._call("render", camera, settings)

    # --- a render the caller does not wait for (the add-on's progressive preview) --------
    def render_begin(self, camera, settings=None):
        """Send a render and return at once: the caller stays free while the worker draws.
        render_ready() says when the image has come, render_end() returns it (or raises what
        render would). Any other call first collects the image and drops it."""
        self._send("render", (camera, settings), None)
        self._pending = "render"

    def render_ready(self):
        """True once the render sent by render_begin has an answer (or the worker died)."""
        return self._pending is None or self._answers is None or not self._answers.empty() \
            or self._proc is None or self._proc.poll() is not None

    def render_end(self, timeout=None):
        """The image of the render sent by render_begin (waiting for it when not ready)."""
        if self._pending is None:
            raise WorkerError("tracer worker: render_end without a render_begin")
        self._pending = None
        return self._receive("render", timeout)

    @property
    def stats(self):
        return self._call("stats")

    @property
    def pid(self):
        return None if self._proc is None else self._proc.pid

    def close(self):
        if self._proc is not None and self._proc.poll() is None:
            try:
                self._exchange("quit", (), 10)
            except Exception:
                pass
        self._kill()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def main():
    # Answers go to the real stdout only; anything the GL stack prints goes to stderr.
    out = os.fdopen(os.dup(sys.stdout.fileno()), "wb")
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())
    serve(sys.stdin.buffer, out)


if __name__ == "__main__":
    main()
