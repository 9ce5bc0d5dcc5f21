# SPDX-License-Identifier: GPL-3.0-or-later
import json

import numpy as np
import pytest

from groom import GroomParams, Scalp, generate, list_presets, load_preset, save_preset
from hairio import InputError

REQUIRED = {"short_intelligent", "long_straight", "wavy", "curly", "parted"}


def test_the_required_presets_exist():
    assert REQUIRED <= set(list_presets())


@pytest.mark.parametrize("name", sorted(REQUIRED))
def test_every_preset_grows_finite_hair_on_the_default_scalp(scalp, name):
    preset = load_preset(name)
    keys = preset.keys_on(scalp)
    r = generate(scalp, keys, preset.params.replace(count=300))
    assert r.strands.num_strands == 300
    assert np.isfinite(r.strands.points).all()
    # Key roots sit on the scalp.
    _, _, on = scalp.closest_points(np.array([k.root for k in keys]))
    np.testing.assert_allclose(on, [k.root for k in keys], atol=1e-9)


def test_short_intelligent_is_one_key_with_the_intelligence_flag():
    p = load_preset("short_intelligent")
    assert len(p.key_specs) == 1 and p.params.intelligence


def test_parted_has_two_groups_that_do_not_mix_in_front_of_the_crown(scalp):
    p = load_preset("parted")
    keys = p.keys_on(scalp)
    assert {k.group for k in keys} == {0, 1}
    r = generate(scalp, keys, p.params.replace(count=2000))
    groups = np.array([k.group for k in keys])
    parting = p.params.parting
    side = (r.roots - parting["point"]) @ parting["normal"] > 0
    in_front = (r.roots - parting["end"]) @ np.asarray(p.params.front) >= 0
    used = groups[r.guides]
    assert ((used == (side & in_front)[:, None]) | (r.guide_weights == 0)).all()
    # The parting stops at the crown: behind it both sides follow the same keys.
    assert (side & ~in_front).any() and (used[side & ~in_front] == 0).all()


def test_keys_land_on_the_nearest_point_of_another_scalp(scalp):
    # The same head, moved and enlarged: key roots follow it onto its surface.
    other = Scalp(scalp.vertices * 1.2 + [0.5, 0, 0], scalp.triangles)
    keys = load_preset("wavy").keys_on(other)
    _, _, on = other.closest_points(np.array([k.root for k in keys]))
    np.testing.assert_allclose(on, [k.root for k in keys], atol=1e-9)
    assert min(k.root[0] for k in keys) > 0.3


def test_unknown_preset_lists_the_available_ones():
    with pytest.raises(InputError) as e:
        load_preset("mohawk")
    for name in REQUIRED:
        assert name in str(e.value)


def test_saved_presets_load_back_with_the_same_keys_and_params(tmp_path, scalp):
    keys = load_preset("curly").keys_on(scalp)[:3]
    params = GroomParams(count=77, tidiness=0.4)
    path = tmp_path / "mine.json"
    save_preset(path, keys, params)
    back = load_preset(str(path))
    assert back.params == params
    for a, b in zip(keys, back.keys_on(scalp)):
        np.testing.assert_allclose(a.points, b.points, atol=1e-12)
        assert a.kind == b.kind


@pytest.mark.parametrize("mutate, word", [
    (lambda d: d["keys"][0].update(profile=[[0, 0, 0], [0, float("nan"), 1]]), "NaN"),
    (lambda d: d["params"].update(tidyness=1), "tidyness"),
    (lambda d: d["keys"][0].update(anchor={"where": [0, 0, 1]}), "anchor"),
    (lambda d: d.update(keys=[]), "no keys"),
])
def test_broken_preset_files_are_rejected_clearly(tmp_path, mutate, word):
    data = json.loads(open(load_preset.__globals__["PRESET_DIR"] / "short_intelligent.json").read())
    mutate(data)
    path = tmp_path / "broken.json"
    path.write_text(json.dumps(data))
    with pytest.raises(InputError, match=word):
        load_preset(str(path))


@pytest.mark.parametrize("text,match", [
    ('{"params": {}, "keys": 5}', "'keys' must be a list of key objects, got int"),
    ('{"params": {}, "keys": {"a": 1}}', "'keys' must be a list of key objects, got dict"),
    ('{"params": {}, "keys": ' + "[" * 100000 + "]" * 100000 + "}", "cannot read it as JSON"),
    ('{"keys": [], "params": ' + '{"a":' * 100000 + "1" + "}" * 100000 + "}", "cannot read it as JSON"),
])
def test_a_preset_of_the_wrong_shape_is_refused(tmp_path, text, match):
    path = tmp_path / "bad.json"
    path.write_text(text)
    with pytest.raises(InputError, match=match):
        load_preset(str(path))
