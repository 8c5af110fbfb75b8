"""The compiled pole design and retune (ugens.modal_retune) against an independent
vectorised numpy computation of the same formulas (complex arithmetic, as first written)."""

import numpy as np

from ugens.modal import TOP_BAND_ROWS
from ugens.modal_retune import LEAVING_FADE, TOP_BAND, pole_rows, retune_state

FS = 48000.0


def reference_poles(freqs, decays, fs, band):
    """(c1, c2, s, d / g), sin2, inv with numpy: the band ratio from the complex responses."""
    R = np.exp(-decays / fs)
    theta = 2.0 * np.pi * freqs / fs
    ok = freqs < fs / 2
    c1 = np.where(ok, 2.0 * R * np.cos(theta), 0.0)
    c2 = np.where(ok, R * R, 0.0)
    s = np.where(ok, R * np.sin(theta), 1.0)
    if band:
        z1 = np.exp(-1j * TOP_BAND)[:, None]
        w = 2.0 * np.pi * freqs
        g = s / fs
        discrete = g * z1 / (1.0 - 2.0 * R * np.cos(theta) * z1 + R * R * z1 * z1)
        continuous = w / ((1j * TOP_BAND[:, None] * fs + decays) ** 2 + w * w)
        weight = 1.0 / np.abs(continuous) ** 2
        d = (weight * (continuous - discrete).real).sum(axis=0) / weight.sum(axis=0)
        ratio = np.where(ok, d / g, 0.0)
    else:
        ratio = np.where(ok, theta / (12.0 * s), 0.0)
    sounding = c2 > 0
    sin2 = np.maximum(1.0 - c1 * c1 / (4 * np.where(sounding, c2, 1.0)), 1e-12)
    inv = np.where(sounding, 1.0 / (np.where(sounding, c2, 1.0) * sin2), 0.0)
    return np.stack([c1, c2, np.where(ok, s, 0.0), ratio]), np.where(sounding, sin2, 1.0), inv


def reference_retune(coef, fresh, old_poles, new_poles, y1, y2, fp, fs):
    """New (coef, y1, y2) and the kink correction, with complex numpy arrays."""
    c1, c2, g_old = coef[:3]
    kink_old = old_poles[3] * old_poles[2]
    kink_new = new_poles[3] * new_poles[2]
    new = fresh.copy()
    old = c2 > 0.0
    r = np.sqrt(np.where(old, c2, 1.0))
    cos_t = np.where(old, c1 / (2.0 * r), 1.0)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t * cos_t, 1e-24))
    leaving = old & (new[1] <= 0.0)
    shrink = np.minimum(1.0, np.exp(-np.log(1000.0) / (LEAVING_FADE * fs)) / r)
    new[0] = np.where(leaving, c1 * shrink, new[0])
    new[1] = np.where(leaving, c2 * shrink * shrink, new[1])
    kink_new = np.where(leaving, kink_old, kink_new)
    keep = old & (new[1] > 0.0)
    r_new = np.sqrt(np.where(keep, new[1], 1.0))
    cos_n = np.where(keep, new[0] / (2.0 * r_new), 1.0)
    sin_n = np.sqrt(np.maximum(1.0 - cos_n * cos_n, 1e-24))
    pole = r * (cos_t + 1j * sin_t)
    pole_new = r_new * (cos_n + 1j * sin_n)
    z = (y1 * cos_t - r * y2) / sin_t + 1j * y1
    z0 = pole * (z + fp * g_old / (r * sin_t))
    virtual = z0 / pole_new - fp * new[2] / (r_new * sin_n)
    theta, theta_new = np.arctan2(sin_t, cos_t), np.arctan2(sin_n, cos_n)
    sine = kink_new - kink_old
    cosine = -np.log(r_new) * kink_new / theta_new + np.log(r) * kink_old / theta
    correction = np.sum(np.where(keep, z0.real * sine - z0.imag * cosine, 0.0))
    return new, np.where(keep, virtual.imag, 0.0), np.where(keep, (virtual / pole_new).imag, 0.0), correction


def compiled_poles(freqs, decays, band):
    k = freqs.size
    poles, sin2, inv = np.empty((4, k)), np.empty(k), np.empty(k)
    pole_rows(freqs, decays, 1.0, 1.0, FS, band, TOP_BAND_ROWS, poles, sin2, inv)
    return poles, sin2, inv


def random_bank(rng, k=240):
    """Modes from 40 Hz to past Nyquist (some leave or enter the band when retuned)."""
    freqs = np.sort(rng.uniform(40.0, 26000.0, k))
    decays = rng.uniform(0.5, 3000.0, k)
    return freqs, decays


def test_pole_rows_match_numpy_for_both_fits():
    freqs, decays = random_bank(np.random.default_rng(1))
    for band in (False, True):
        got = compiled_poles(freqs, decays, band)
        want = reference_poles(freqs, decays, FS, band)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_allclose(g, w, rtol=1e-12, atol=0.0)
        assert np.any(got[0][3] == 0.0) and np.all(np.isfinite(got[0]))  # silent modes above Nyquist


def test_retune_state_matches_numpy_for_leaving_entering_and_kept_modes():
    rng = np.random.default_rng(2)
    freqs, decays = random_bank(rng)
    gains = rng.uniform(-1.0, 1.0, freqs.size) / FS
    for band in (False, True):
        for size in (0.6, 1.7):  # modes pushed over Nyquist, and modes coming back
            old_poles = compiled_poles(freqs, decays, band)[0]
            new_poles = compiled_poles(freqs / np.sqrt(size), decays / np.sqrt(size), band)[0]
            coef = np.stack(
                [old_poles[0], old_poles[1], old_poles[2] * gains, old_poles[2] * gains * old_poles[3]]
            )
            fresh = np.stack(
                [new_poles[0], new_poles[1], new_poles[2] * gains, new_poles[2] * gains * new_poles[3]]
            )
            y1 = np.where(coef[1] > 0, rng.normal(size=freqs.size), 0.0)
            y2 = np.where(coef[1] > 0, rng.normal(size=freqs.size), 0.0)
            fp = 0.37
            want = reference_retune(coef, fresh, old_poles, new_poles, y1, y2, fp, FS)
            leaving = (coef[1] > 0) & (fresh[1] <= 0)
            entering = (coef[1] <= 0) & (fresh[1] > 0)
            assert leaving.any() if size < 1 else entering.any()
            tuning = np.full((6, freqs.size), np.nan)
            correction = retune_state(coef, fresh, old_poles, new_poles, y1, y2, fp, FS, tuning)
            assert_retuned(coef, y1, y2, correction, want)
            # back to size 1 from the retuned state: the kept tuning is reused
            want = reference_retune(
                coef, fresh_1 := fresh_at(old_poles, gains), new_poles, old_poles, y1, y2, fp, FS
            )
            correction = retune_state(coef, fresh_1, new_poles, old_poles, y1, y2, fp, FS, tuning)
            assert_retuned(coef, y1, y2, correction, want)


def fresh_at(poles, gains):
    return np.stack([poles[0], poles[1], poles[2] * gains, poles[2] * gains * poles[3]])


def assert_retuned(coef, y1, y2, correction, want):
    np.testing.assert_allclose(coef, want[0], rtol=1e-12, atol=0.0)
    scale = np.abs(want[1]).max()
    np.testing.assert_allclose(y1, want[1], rtol=1e-12, atol=1e-13 * scale)
    np.testing.assert_allclose(y2, want[2], rtol=1e-12, atol=1e-13 * scale)
    assert abs(correction - want[3]) <= 1e-12 * abs(want[3]) + 1e-15


def test_each_design_rounds_where_its_caller_runs():
    """One resonator formula, two evaluations: ModalBank's compiled rows take libm's exp, sin
    and cos per mode (Python's math module, the same library), ugens.modal.design numpy's
    vectorised ones (with AVX-512 the two exps differ in some last bits, so renders keep
    the bits of where their design ran)."""
    import math

    from ugens.modal import design, mode_poles

    rng = np.random.default_rng(5)
    freqs, decays = rng.uniform(20.0, 30000.0, 4000), rng.uniform(0.1, 3000.0, 4000)
    c1, c2, s, _ = mode_poles(freqs, decays, FS)
    per_mode = [(math.exp(-d / FS), 2.0 * math.pi * f / FS) for f, d in zip(freqs, decays, strict=True)]
    libm = np.array([(2.0 * r * math.cos(t), r * r, r * math.sin(t)) for r, t in per_mode]).T
    sounding = freqs < FS / 2
    libm[:, ~sounding] = 0.0
    np.testing.assert_array_equal(np.stack([c1, c2, s]), libm)
    r, theta = np.exp(-decays / FS), 2.0 * np.pi * freqs / FS
    vectorised = np.where(sounding, [2.0 * r * np.cos(theta), r * r, r * np.sin(theta)], 0.0)
    np.testing.assert_array_equal(np.stack(design(freqs, decays, FS)), vectorised)
