# SPDX-License-Identifier: GPL-3.0-or-later
"""Write a file completely or not at all: a failed export leaves no half file; and find out
before the work whether the file can be written at all."""
import contextlib
import os
import shutil
import tempfile

from .validate import InputError


@contextlib.contextmanager
def _beside(path):
    """Yield (fd, name) of a new private temporary file in `path`'s folder (so the final
    os.replace is atomic: same file system); rename it onto `path` on success, with the
    permissions open() would give. On any exception the temporary file is removed and
    `path` is untouched."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FileNotFoundError(f"output folder {folder!r} does not exist; create it first")
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=os.path.basename(path), dir=folder)
    try:
        yield fd, tmp
        umask = os.umask(0)   # mkstemp made the file 0600
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


@contextlib.contextmanager
def atomic_write(path, mode="wb"):
    """Yield a file object on a temporary name beside `path`; rename onto `path` on success."""
    with _beside(path) as (fd, _tmp), os.fdopen(fd, mode) as f:
        yield f


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary file name beside `path`, with the same extension (for libraries that
    choose the format by it and write by name); rename it onto `path` on success. On any
    exception the temporary file is removed and `path` is untouched."""
    with _beside(path) as (fd, tmp):
        os.close(fd)
        yield tmp


def check_destination(path, what=None, expected_bytes=0):
    """InputError before any work when `path` cannot be written: it is a folder, its folder
    is missing or refuses a new file (tried with a real temporary file, as atomic_write
    will make one), or its disk has less room than `expected_bytes`. `what` names the
    input in the message (default: the path). A disk may still fill up while the work
    runs; atomic_write then leaves no half file."""
    path = os.fspath(path)
    name = what or path
    if os.path.isdir(path):
        raise InputError(f"{name}: is a folder; give a file name, e.g. {os.path.join(path, 'hair' + '.png')!r}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"{name}: folder {folder!r} does not exist; create it first")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=folder)
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise InputError(f"{name}: cannot write in {folder!r} ({e.strerror or e}); choose a writable place") from None
    if expected_bytes:
        free = shutil.disk_usage(folder).free
        if expected_bytes > free:
            raise InputError(f"{name}: needs about {expected_bytes / 2**20:,.1f} MiB but {folder!r} has "
                             f"{free / 2**20:,.1f} MiB free; free some space or write elsewhere")
