"""The committed sample equals a fresh generation by brdffit.sample."""

from __future__ import annotations

import numpy as np

import brdffit
from brdffit import sample


def test_committed_sample_equals_fresh_generation(tmp_path):
    committed = brdffit.load(sample.DEFAULT_PATH)
    fresh = sample.generate()
    for f in ("wi", "wo", "values", "weights"):
        np.testing.assert_array_equal(np.asarray(getattr(committed, f)), np.asarray(getattr(fresh, f)), err_msg=f)
    assert committed.meta == fresh.meta
    # and the file written now reads back identically
    again = brdffit.load(sample.write(tmp_path / "s.exr"))
    np.testing.assert_array_equal(np.asarray(again.values), np.asarray(committed.values))


def test_sample_is_plausible():
    m = brdffit.load(sample.DEFAULT_PATH)
    wi, wo = brdffit.ubo_pairs()
    truth = sample.ground_truth(wi, wo)
    valid = m.valid_mask()
    assert m.grid == "ubo81" and 0 < m.meta["clipped"] == int((~valid).sum()) < 100
    # noise and 8-bit quantisation: close to the truth but not equal to it
    rel = np.abs(np.asarray(m.values)[valid] - truth[valid]) / (truth[valid] + 0.01)
    assert 0 < np.median(rel) < 0.05
    codes = brdffit.io.images.linear_to_srgb(np.asarray(m.values)[valid] / sample.EXPOSURE) * 255
    np.testing.assert_allclose(codes, np.round(codes), atol=1e-3)  # values sit on 8-bit sRGB codes
