# SPDX-License-Identifier: GPL-3.0-or-later
"""A private X display for tests that need one (the tracer under GLX): Xvfb on a free
display number, ready when it accepts connections, stopped by the caller."""
import os
import shutil
import socket
import subprocess
import tempfile
import time

SOCKET_DIR = "/tmp/.X11-unix"
FIRST_DISPLAY = 90       # clear of the low numbers desktops and ssh forwarding take


class XvfbError(RuntimeError):
    pass


def display_in_use(n):
    return os.path.exists(f"/tmp/.X{n}-lock") or os.path.exists(f"{SOCKET_DIR}/X{n}")


def free_display(first=FIRST_DISPLAY, count=500):
    for n in range(first, first + count):
        if not display_in_use(n):
            return n
    raise XvfbError(f"no free X display number in :{first}..:{first + count - 1}")


def _accepts_connections(n):
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(1.0)
        try:
            s.connect(f"{SOCKET_DIR}/X{n}")
        except OSError:
            return False
    return True


def _lock_owner(n):
    try:
        with open(f"/tmp/.X{n}-lock") as f:
            return int(f.read().strip() or 0)
    except (OSError, ValueError):
        return None


class Xvfb:
    """`Xvfb :N -screen 0 64x64x24 -nolisten tcp` on the first free N; `display` is ":N"."""

    def __init__(self, timeout=10.0, attempts=5):
        exe = shutil.which("Xvfb")
        if exe is None:
            raise XvfbError("Xvfb is not installed; the GLX tests need it: install xvfb "
                            "(Debian/Ubuntu: apt-get install xvfb), or set DISPLAY to a running X server")
        self.proc = None
        self.display = None
        self._last_words = ""
        first = FIRST_DISPLAY
        for _ in range(attempts):
            n = free_display(first)
            if self._start(exe, n, timeout):
                self.display = f":{n}"
                return
            first = n + 1       # another server took the number between the check and the start
        raise XvfbError(f"Xvfb did not start after {attempts} attempts; last words: {self._last_words!r}")

    def _start(self, exe, n, timeout):
        log = tempfile.TemporaryFile()
        proc = subprocess.Popen([exe, f":{n}", "-screen", "0", "64x64x24", "-nolisten", "tcp"],
                                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=log)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                break
            # The lock names the server that holds the number: ours, not one that raced us.
            if _lock_owner(n) == proc.pid and _accepts_connections(n):
                self.proc = proc
                log.close()
                return True
            time.sleep(0.05)
        else:
            _stop(proc)
            log.seek(0)
            raise XvfbError(f"Xvfb :{n} accepted no connection within {timeout:.0f} s: "
                            f"{log.read().decode(errors='replace')[-500:]!r}")
        log.seek(0)
        self._last_words = log.read().decode(errors="replace")[-500:]
        log.close()
        return False

    def stop(self):
        proc, self.proc = self.proc, None
        if proc is not None:
            _stop(proc)


def _stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5)
