# SPDX-License-Identifier: GPL-3.0-or-later
import pytest



@pytest.fixture(scope="session")
def renderer():
    """One renderer (one EGL context) for the whole session, as in production."""
    from tracer import Renderer
    return Renderer()


