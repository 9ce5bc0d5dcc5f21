# SPDX-License-Identifier: GPL-3.0-or-later
import json

import pytest

from groom import GroomParams
from hairio import InputError


def test_params_round_trip_through_json():
    p = GroomParams(count=123, tidiness=0.3, parting={"point": [0, 0, 0], "normal": [1, 0, 0]})
    q = GroomParams.from_dict(json.loads(json.dumps(p.to_dict())))
    assert q == p


def test_unknown_parameter_names_are_rejected_by_name():
    with pytest.raises(InputError, match="colour"):
        GroomParams.from_dict({"colour": [1, 0, 0]})


@pytest.mark.parametrize("name, value", [
    ("count", 0), ("count", 1.5), ("tidiness", 1.5), ("n_influence", -1), ("n_influence", float("nan")),
    ("min_length", 0.0), ("theta_max", -0.1), ("neighbour_mode", "nearest"), ("resolution_mode", "auto"),
    ("tolerance", 0.0), ("points_per_strand", 1), ("color", [1, 2, 3]), ("color", [0.1, 0.2]),
    ("up", [0, 0, 0]), ("intelligence", "yes"), ("alpha_tip", 2), ("radius_mode", "cone"),
    ("parting", {"point": [0, 0, 0]}),
])
def test_bad_parameter_values_are_rejected_naming_the_parameter(name, value):
    with pytest.raises(InputError, match=name.split("_")[0]):
        GroomParams.from_dict({name: value})


def test_min_length_above_max_length_is_rejected():
    with pytest.raises(InputError, match="min_length"):
        GroomParams(min_length=0.9, max_length=0.5)
