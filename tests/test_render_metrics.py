"""Validation metrics against values computed independently of brdffit: PSNR by hand (numpy and
colour-science's sRGB encoding), FLIP with flip-evaluator's own API on the same tone-mapped images,
RMSE / relative RMSE by hand, the overall PSNR pooled over lights (10 log10 of 1 / mean MSE)."""

from __future__ import annotations

import numpy as np
import pytest

from brdffit.render.metrics import image_metrics, summarise, table_metrics


def _pair(seed=0, h=24, w=20):
    rng = np.random.default_rng(seed)
    ref = rng.uniform(0.0, 0.9, (h, w, 3))
    test = np.clip(ref + rng.normal(0, 0.05, ref.shape), 0, None)
    yy, xx = np.mgrid[:h, :w]
    mask = (yy - h / 2) ** 2 + (xx - w / 2) ** 2 < (min(h, w) / 2.2) ** 2
    return ref, test, mask


def _encode(x):
    import colour

    return colour.models.eotf_inverse_sRGB(np.clip(x, 0, 1))


def test_psnr_rmse_flip_of_one_pair_by_hand():
    import flip_evaluator

    ref, test, mask = _pair()
    scale = 1.0
    got = image_metrics(ref, test, mask, scale=scale)
    d = (test - ref)[mask]
    assert got["rmse"] == pytest.approx(np.sqrt(np.mean(d**2)), rel=1e-12)
    assert got["rel_rmse"] == pytest.approx(np.sqrt(np.mean(d**2) / np.mean(ref[mask] ** 2)), rel=1e-12)
    a, b = _encode(ref * scale), _encode(test * scale)
    mse = np.mean((a[mask] - b[mask]) ** 2)
    assert got["psnr"] == pytest.approx(10 * np.log10(1 / mse), rel=1e-9)
    flip_map, _, _ = flip_evaluator.evaluate(a.astype(np.float32), b.astype(np.float32), "LDR", inputsRGB=True,
                                             applyMagma=False, computeMeanError=False)
    expect_flip = float(np.mean(np.asarray(flip_map).reshape(mask.shape)[mask]))
    assert got["flip"] == pytest.approx(expect_flip, rel=1e-6)
    assert 0.0 < got["flip"] < 1.0


def test_psnr_known_value():
    # tone-mapped difference 0.1 everywhere on the mask -> MSE 0.01 -> PSNR 20 dB exactly
    ref = np.full((8, 8, 3), 0.5)
    a = _encode(ref)
    test_encoded = a - 0.1
    import colour

    test = colour.models.eotf_sRGB(test_encoded)
    mask = np.ones((8, 8), bool)
    assert image_metrics(ref, test, mask, scale=1.0)["psnr"] == pytest.approx(20.0, abs=1e-9)


def test_default_exposure_is_the_reference_percentile():
    ref, test, mask = _pair(1)
    peak = np.percentile(ref.max(axis=-1)[mask], 99.5)
    assert image_metrics(ref, test, mask)["psnr"] == pytest.approx(image_metrics(ref, test, mask, scale=1 / peak)["psnr"], rel=1e-12)
    assert image_metrics(ref, test, mask)["psnr"] != pytest.approx(image_metrics(ref, test, mask, scale=1.0)["psnr"], rel=1e-6)


def test_overall_metrics_pool_the_lights():
    pairs = [_pair(2), _pair(3)]
    mask = pairs[0][2]
    per = [image_metrics(r, t, mask, scale=1.0) for r, t, _ in pairs]
    refs = np.stack([p[0] for p in pairs])
    tests = np.stack([p[1] for p in pairs])
    overall = summarise(per, refs, tests, mask)
    mses = []
    for r, t, _ in pairs:
        a, b = _encode(r), _encode(t)
        mses.append(np.mean((a[mask] - b[mask]) ** 2))
    assert overall["psnr"] == pytest.approx(10 * np.log10(1 / np.mean(mses)), rel=1e-9)
    d = np.concatenate([(t - r)[mask].ravel() for r, t, _ in pairs])
    assert overall["rmse"] == pytest.approx(np.sqrt(np.mean(d**2)), rel=1e-12)
    assert overall["flip"] == pytest.approx(np.mean([p["flip"] for p in per]), rel=1e-12)


# cos(theta_light) of the UBO-81 rows, from docs/conventions.md#conventions (rings of 1, 6, 12, 18, 20, 24 directions at
# 0, 15, ..., 75 degrees): the log residual of docs/fitting.md#fitting is ln(1 + f cos) - ln(1 + f_ref cos).
COS_LIGHT = np.repeat(np.cos(np.radians([0, 15, 30, 45, 60, 75])), [1, 6, 12, 18, 20, 24])


def test_table_metrics_by_hand():
    rng = np.random.default_rng(4)
    ref = rng.uniform(0, 2, (81, 81, 3))
    fit = ref * rng.uniform(0.8, 1.2, ref.shape)
    valid = np.ones((81, 81), bool)
    valid[3, :] = False
    got = table_metrics(ref, fit, valid)
    r, f = ref[valid], fit[valid]
    c = np.broadcast_to(COS_LIGHT[:, None, None], ref.shape)[valid]
    assert got["rmse"] == pytest.approx(np.sqrt(np.mean((f - r) ** 2)), rel=1e-12)
    assert got["rel_rmse"] == pytest.approx(np.sqrt(np.mean((f - r) ** 2) / np.mean(r**2)), rel=1e-12)
    assert got["log_rmse"] == pytest.approx(np.sqrt(np.mean((np.log1p(f * c) - np.log1p(r * c)) ** 2)), rel=1e-12)
    assert got["valid_pairs"] == 81 * 80
