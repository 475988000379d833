"""The geometry-only form-factor cache: hits, material changes, corruption."""

from __future__ import annotations

import numpy as np

import radiosity
from radiosity.methods.uniform.cache import FormFactorCache


def cornell():
    return radiosity.load_scene(radiosity.bundled_scene("cornell_box"))


def test_cache_hit_reproduces_radiosity_exactly():
    cold = radiosity.solve(cornell(), preset="draft")
    warm = radiosity.solve(cornell(), preset="draft")
    assert not cold.cache_hit and warm.cache_hit
    np.testing.assert_array_equal(cold.radiosity, warm.radiosity)
    assert warm.timings["form factors"] == 0.0


def test_changing_only_reflectance_reuses_form_factors():
    scene = cornell()
    first = radiosity.solve(scene, preset="draft")
    repainted = scene.object_material("back_wall", reflectance=[0.2, 0.2, 0.8])
    second = radiosity.solve(repainted, preset="draft")
    assert second.cache_hit
    before, after = first.object_radiosity()["back_wall"], second.object_radiosity()["back_wall"]
    assert after[2] / after[0] > 2 * before[2] / before[0]  # the wall turned blue
    # and a cold solve of the repainted scene gives the same answer
    cold = radiosity.solve(repainted, preset="draft", cache=False)
    np.testing.assert_allclose(second.radiosity, cold.radiosity, rtol=1e-12, atol=1e-15)


def test_different_accuracy_settings_do_not_share_an_entry():
    radiosity.solve(cornell(), preset="draft")
    other = radiosity.solve(cornell(), preset="draft", visibility_samples=3)
    assert not other.cache_hit


def test_corrupted_entry_is_detected_and_rebuilt():
    scene = cornell()
    cold = radiosity.solve(scene, preset="draft")
    cache = FormFactorCache.default()
    entries = list(cache.folder.glob("F-*.npz"))
    assert len(entries) == 1
    data = bytearray(entries[0].read_bytes())
    data[len(data) // 2] ^= 0xFF
    entries[0].write_bytes(bytes(data))
    again = radiosity.solve(scene, preset="draft")
    assert not again.cache_hit
    np.testing.assert_allclose(again.radiosity, cold.radiosity, rtol=1e-12)
    assert radiosity.solve(scene, preset="draft").cache_hit


def test_truncated_entry_is_rebuilt():
    scene = cornell()
    radiosity.solve(scene, preset="draft")
    entry = next(FormFactorCache.default().folder.glob("F-*.npz"))
    entry.write_bytes(entry.read_bytes()[:100])
    assert not radiosity.solve(scene, preset="draft").cache_hit
