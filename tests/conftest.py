# SPDX-License-Identifier: GPL-3.0-or-later
import os
import pathlib
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

# Real hair files made by others live beside the repository, never inside it.
DATA = pathlib.Path(os.environ.get("HAIR_DATA", ROOT.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data():
    if not DATA.is_dir():
        pytest.fail(f"real data folder {DATA} is missing; put ../shared beside the checkout or set HAIR_DATA")
    return DATA


@pytest.fixture
def spare_takes(monkeypatch):
    """A list that records, for every shared array groom makes from here on, whether it took
    the memory of one that went inside groom.processes.recycling() (True) or new pages."""
    from groom import processes
    taken, real = [], processes._take_spare

    def watched(nbytes):
        got = real(nbytes)
        taken.append(got[0] is not None)
        return got
    monkeypatch.setattr(processes, "_take_spare", watched)
    return taken


@pytest.fixture
def colliders_built(monkeypatch):
    """A list that records the thread of every groom Collider built from here on (groom's
    cache of colliders emptied first, so none is found made)."""
    import threading
    from collections import OrderedDict
    from groom import collide
    monkeypatch.setattr(collide, "_CACHE", OrderedDict())
    built, real = [], collide.Collider.__init__

    def counted(self, *args, **kwargs):
        built.append(threading.current_thread().name)
        real(self, *args, **kwargs)
    monkeypatch.setattr(collide.Collider, "__init__", counted)
    return built
