"""HairModel: eval, pdf and sample over arrays, against single calls and the furnace."""

import numpy as np
import pytest

import tress

BROWN = "Chiang(beta_m: 0.3, pigment: Melanin(eumelanin: 1.3))"
# Non-absorbing and energy conserving: everything that arrives leaves (the white furnace).
WHITE = "Chiang(beta_m: 0.3, beta_n: 0.3, pigment: SigmaA(0, 0, 0))"


def unit_vectors(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def direction(theta_o):
    """The direction at inclination theta_o (radians) with azimuth pi/2: toward the viewer."""
    return np.array([np.sin(theta_o), 0.0, np.cos(theta_o)])


@pytest.fixture
def inputs():
    rng = np.random.default_rng(3)
    n = 64
    return {
        "wo": unit_vectors(rng, n),
        "wi": unit_vectors(rng, n),
        "h": rng.uniform(-1, 1, n),
        "u": rng.uniform(0, 1, (n, 4)),
    }


@pytest.mark.parametrize("model", [BROWN, WHITE, "DEon()", "Marschner()", "LambertianFiber()"])
def test_arrays_give_what_single_calls_give(model, inputs):
    m = tress.HairModel(model)
    wo, wi, h, u = inputs["wo"], inputs["wi"], inputs["h"], inputs["u"]
    f = m.eval(wo, wi, h)
    pdf = m.pdf(wo, wi, h)
    swi, sf, spdf = m.sample(wo, h, u)
    assert f.shape == (64, 3) and f.dtype == np.float32
    assert pdf.shape == (64,) and pdf.dtype == np.float32
    assert swi.shape == (64, 3) and sf.shape == (64, 3) and spdf.shape == (64,)
    for i in range(64):
        np.testing.assert_array_equal(f[i], m.eval(wo[i], wi[i], h[i]))
        assert pdf[i] == m.pdf(wo[i], wi[i], h[i])
        one = m.sample(wo[i], h[i], u[i])
        np.testing.assert_array_equal(swi[i], one[0])
        np.testing.assert_array_equal(sf[i], one[1])
        assert spdf[i] == one[2]
    assert isinstance(m.pdf(wo[0], wi[0], h[0]), float)
    assert m.eval(wo[0], wi[0], h[0]).shape == (3,)


def test_single_values_apply_to_every_row(inputs):
    m = tress.HairModel(BROWN)
    wo, wi, h = inputs["wo"], inputs["wi"], inputs["h"]
    n = len(wi)
    np.testing.assert_array_equal(
        m.eval(wo[0], wi, 0.25), m.eval(np.tile(wo[0], (n, 1)), wi, np.full(n, 0.25))
    )
    np.testing.assert_array_equal(m.pdf(wo, wi[5], h), m.pdf(wo, np.tile(wi[5], (n, 1)), h))


def test_directions_are_normalised(inputs):
    m = tress.HairModel(BROWN)
    wo, wi, h = inputs["wo"], inputs["wi"], inputs["h"]
    # Equal up to the rounding of the normalisation (f32).
    np.testing.assert_allclose(m.eval(3 * wo, 0.5 * wi, h), m.eval(wo, wi, h), rtol=1e-5)


def test_samples_agree_with_eval_and_pdf():
    m = tress.HairModel(BROWN)
    rng = np.random.default_rng(11)
    n = 4000
    wo = unit_vectors(rng, n)
    h = rng.uniform(-1, 1, n)
    wi, f, pdf = m.sample(wo, h, rng.uniform(0, 1, (n, 4)))
    drawn = pdf > 0
    assert drawn.mean() > 0.99
    np.testing.assert_allclose(np.linalg.norm(wi[drawn], axis=1), 1, atol=1e-4)
    # What was sampled has the density `pdf` gives it, and the value `eval` gives it.
    again = m.pdf(wo[drawn], wi[drawn], h[drawn])
    assert (again > 0).all()
    np.testing.assert_allclose(again, pdf[drawn], rtol=2e-3)
    np.testing.assert_allclose(m.eval(wo[drawn], wi[drawn], h[drawn]), f[drawn], rtol=2e-3, atol=1e-7)


def test_sample_weight_draws_the_same_directions_with_the_same_mean():
    m = tress.HairModel(BROWN)
    rng = np.random.default_rng(12)
    n = 100_000
    wo, h, u = direction(np.radians(20)), rng.uniform(-1, 1, n), rng.uniform(0, 1, (n, 4))
    wi, f, pdf = m.sample(wo, h, u)
    wi_weighted, weight = m.sample_weight(wo, h, u)
    np.testing.assert_array_equal(wi_weighted, wi)
    # Paired: the difference of the two weights has far less noise than either.
    ratio = np.where(pdf[:, None] > 0, f / np.maximum(pdf, 1e-30)[:, None], 0.0)
    d = weight.astype(np.float64) - ratio
    assert (np.abs(d.mean(axis=0)) < 5 * d.std(axis=0) / np.sqrt(n) + 1e-6).all()
    assert not np.allclose(weight, ratio)  # Chiang's lobe weight is not f / pdf row by row


def furnace(model, theta_o, n, seed):
    """Mean and standard error of f/pdf over n importance samples with h uniform: the albedo
    (eval includes cos θ_i)."""
    rng = np.random.default_rng(seed)
    h = rng.uniform(-1, 1, n)
    _, f, pdf = model.sample(direction(theta_o), h, rng.uniform(0, 1, (n, 4)))
    w = np.where(pdf[:, None] > 0, f / np.maximum(pdf, 1e-30)[:, None], 0.0)
    return w.mean(axis=0), w.std(axis=0) / np.sqrt(n)


def uniform_furnace(model, theta_o, n, seed):
    """The same albedo from uniformly distributed directions: mean of 4π·eval."""
    rng = np.random.default_rng(seed)
    wi = unit_vectors(rng, n)
    w = 4 * np.pi * model.eval(direction(theta_o), wi, rng.uniform(-1, 1, n)).astype(np.float64)
    return w.mean(axis=0), w.std(axis=0) / np.sqrt(n)


@pytest.mark.parametrize("theta_o_deg", [-60, 0, 30, 75])
def test_white_furnace(theta_o_deg):
    m = tress.HairModel(WHITE)
    theta_o = np.radians(theta_o_deg)
    mean, se = furnace(m, theta_o, 100_000, seed=theta_o_deg + 100)
    assert (np.abs(mean - 1) < 4 * se + 2e-3).all(), (mean, se)
    # Independently of the sampler: a uniform estimate of the same integral.
    mean, se = uniform_furnace(m, theta_o, 200_000, seed=theta_o_deg + 200)
    assert (np.abs(mean - 1) < 4 * se + 2e-3).all(), (mean, se)


def test_lambertian_fiber_returns_its_albedo():
    m = tress.HairModel("LambertianFiber(albedo: (0.5, 0.3, 0.1))")
    mean, se = furnace(m, np.radians(20), 100_000, seed=5)
    assert (np.abs(mean - [0.5, 0.3, 0.1]) < 4 * se + 1e-3).all(), (mean, se)


def test_absorbing_fibers_return_less():
    mean, _ = furnace(tress.HairModel(BROWN), np.radians(20), 20_000, seed=6)
    assert (mean < 0.9).all() and mean[0] > mean[2]


def test_repr_and_lobes():
    m = tress.HairModel(BROWN)
    assert repr(m).startswith('tress.HairModel("Chiang(') and "eumelanin:1.3" in repr(m)
    assert m.lobes == ["R", "TT", "TRT", "residual"]
    assert set(tress.HAIR_MODELS) >= {"Chiang", "DEon", "Marschner", "LambertianFiber"}


def test_bad_models_raise_valueerror():
    with pytest.raises(ValueError, match="models: .*Chiang"):
        tress.HairModel("Chaing(beta_m: 0.3)")
    with pytest.raises(ValueError, match="beta_m = 5"):
        tress.HairModel("Chiang(beta_m: 5)")


def test_bad_arguments_raise_valueerror(inputs):
    m = tress.HairModel(BROWN)
    wo, wi, h, u = inputs["wo"], inputs["wi"], inputs["h"], inputs["u"]
    bad_h = h.copy()
    bad_h[3] = 1.5
    with pytest.raises(ValueError, match=r"h\[3\] = 1.5 must lie in \[-1, 1\]"):
        m.eval(wo, wi, bad_h)
    bad_wi = wi.copy()
    bad_wi[7] = 0
    with pytest.raises(ValueError, match=r"wi\[7\] = .* is not a direction"):
        m.pdf(wo, bad_wi, h)
    with pytest.raises(ValueError, match=r"wo = .* is not a direction"):
        m.pdf([np.nan, 0, 1], wi, h)
    bad_u = u.copy()
    bad_u[2, 1] = 1.0
    with pytest.raises(ValueError, match=r"u\[2\] = .*must lie in \[0, 1\)"):
        m.sample(wo, h, bad_u)
    with pytest.raises(ValueError, match="wo has 64 rows but h has 63"):
        m.eval(wo, wi, h[:-1])
    with pytest.raises(ValueError, match=r"wi must have shape \(N, 3\) or \(3,\)"):
        m.eval(wo, wi[:, :2], h)
    with pytest.raises(ValueError, match=r"u must have shape \(N, 4\) or \(4,\)"):
        m.sample(wo, h, u[:, :3])


def test_float64_random_numbers_below_one_are_accepted():
    # rng.uniform(0, 1) can return numbers above 1 - 2**-25, which round to 1.0 in f32: the
    # documented albedo example must not fail for them.
    m = tress.HairModel(BROWN)
    below_one = np.nextafter(1.0, 0.0)
    u = np.array([[below_one, 1 - 2.0**-25, 0.5, below_one]])
    wi, f, pdf = m.sample(direction(0.3), [0.1], u)
    assert np.all(np.isfinite(wi)) and np.all(np.isfinite(f)) and np.all(np.isfinite(pdf))
    with pytest.raises(ValueError, match=r"u\[0\] = .*must lie in \[0, 1\)"):
        m.sample(direction(0.3), [0.1], [[1.0, 0.5, 0.5, 0.5]])


def test_directions_and_offsets_get_the_verdict_of_bcsdf_eval():
    # `tress bcsdf eval` reads f32 and normalises with `tress_core::math::unit`: 1e-30 (whose
    # square is 0 in f32) is a direction, 1e-46 (0 in f32) is not; h rounding to 1 is in range.
    m = tress.HairModel(BROWN)
    assert np.isfinite(m.pdf([1e-30, 0, 0], [0, 0, 1e-30], 1 + 1e-9))
    with pytest.raises(ValueError, match=r"wi = .* is not a direction"):
        m.pdf([1, 0, 0], [0, 0, 1e-46], 0.2)
