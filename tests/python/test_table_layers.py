"""Tables and layers from Python: numpy arrays, save/load, vectorised eval and sample."""

import numpy as np
import pytest

import striae


@pytest.fixture(scope="module")
def table():
    return striae.precompute(m=32, n=400, nr=10, seed=1)


def test_table_arrays_and_round_trip(table, tmp_path):
    m = table.m
    assert m == 32
    assert table.phi.shape == (m,) and table.rho_m.shape == (m, m)
    assert table.rho_s.shape == (3, m, m) and table.gamma.shape == (m, m)
    assert table.params["profile"]
    path = tmp_path / "t.npz"
    table.save(path)
    again = striae.Table.load(path)
    np.testing.assert_array_equal(again.rho_s, table.rho_s)
    np.testing.assert_array_equal(again.gamma, table.gamma)


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_sample_agrees_with_eval(table):
    rng = np.random.default_rng(3)
    wo = unit(rng.normal(size=(2000, 3)) * [1, 1, 0] + [0, 0, 1.2])
    u = rng.random((2000, 2))
    wi, weight, pdf, valid = table.sample(wo, u)
    assert wi.shape == (2000, 3) and valid.mean() > 0.9
    f, pdf_eval = table.eval(wo[valid], wi[valid])
    # The sampled pdf is eval's pdf at the sampled direction, and the weight f cos / pdf
    # (each up to the f32 rounding of wi).
    np.testing.assert_allclose(pdf[valid], pdf_eval, rtol=1e-3)
    np.testing.assert_allclose(weight[valid], f * wi[valid, 2] / pdf_eval, rtol=1e-3)
    # No energy is created: the mean weight (directional albedo) is at most 1.
    assert 0.0 < weight.mean() <= 1.0 + 5 * weight.std() / np.sqrt(len(weight))


def test_groove_slices_are_evaluated():
    slices = striae.precompute(m=16, n=100, nr=4, seed=1, groove_slices=3)
    plain = striae.precompute(m=16, n=100, nr=4, seed=1, fresnel="walls")
    assert slices.params["groove_slices"] == 3 and plain.params.get("groove_slices", 0) == 0
    rng = np.random.default_rng(5)
    wo = unit(rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1.2])
    wi = unit(rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1.2])
    f_slices, _ = slices.eval(wo, wi)
    f_plain, _ = plain.eval(wo, wi)
    # The exact groove's slices replace eq. (3): another lobe, the same order of magnitude.
    assert not np.allclose(f_slices, f_plain, rtol=1e-3)
    assert 0.5 < f_slices.mean() / f_plain.mean() < 2.0
    with pytest.raises(striae.StriaeError, match="groove_slices"):
        striae.precompute(m=16, n=100, nr=4, walls="specular", groove_slices=3)


def test_eval_rejects_bad_shapes(table):
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        table.eval(np.zeros((4, 2)), np.zeros((4, 2)))


def test_layers_masks_and_coverage():
    s = striae.layers(setting=1, layers=4, seed=1, res=128)
    masks = s.masks
    assert masks.shape == (4, 128, 128) and masks.dtype == np.float32
    assert s.directions.shape == (4, 2)
    np.testing.assert_allclose(np.linalg.norm(s.directions, axis=1), 1.0, rtol=1e-9)
    # A footprint of one texel at every texel centre covers what the mask says it does, on
    # average over the layer.
    y, x = np.mgrid[0:128, 0:128]
    uv = np.stack([(x.ravel() + 0.5) / 128, 1 - (y.ravel() + 0.5) / 128], axis=1)
    d = np.full_like(uv, 1 / 128)
    cov = s.coverage(uv, d * [1, 0], d * [0, 1])
    assert cov.shape == (128 * 128, 4)
    np.testing.assert_allclose(cov.mean(axis=0), masks.reshape(4, -1).mean(axis=1), atol=0.02)
    with pytest.raises(striae.StriaeError):
        striae.layers(setting=9)
