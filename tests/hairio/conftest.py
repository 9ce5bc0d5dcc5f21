# SPDX-License-Identifier: GPL-3.0-or-later
import pytest

from hairio_scenes import make_wavy


@pytest.fixture
def wavy():
    return make_wavy()

