"""Multi-fractal value noise with a bounded amplitude (paper §6.3: below eps)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from orokit._typing import SeedLike

__all__ = ["fractal_noise", "falloff", "lowpass", "power_law_fit", "power_law_noise", "remove_plane",
           "spectral_noise", "texture_spectrum"]


def _octave(shape: tuple[int, int], cells_per_node: float, rng: np.random.Generator) -> np.ndarray:
    ny, nx = shape
    gy = int(np.ceil(ny / cells_per_node)) + 2
    gx = int(np.ceil(nx / cells_per_node)) + 2
    g = rng.uniform(-1.0, 1.0, (gy, gx)).astype(np.float32)
    up = ndimage.zoom(g, cells_per_node, order=1, prefilter=False, grid_mode=False)
    oy = int(rng.integers(0, max(up.shape[0] - ny, 0) + 1))
    ox = int(rng.integers(0, max(up.shape[1] - nx, 0) + 1))
    return up[oy:oy + ny, ox:ox + nx]


def fractal_noise(
    shape: tuple[int, int],
    res: float,
    *,
    amplitude: float,
    largest_m: float = 2000.0,
    persistence: float = 0.55,
    roughness: np.ndarray | None = None,
    rng: SeedLike = None,
) -> np.ndarray:
    """Sum of value-noise octaves from ``largest_m`` down to 2 cells, ``|noise| <= amplitude``.

    Parameters
    ----------
    shape : (ny, nx) of the raster.
    res : cell size in metres.
    amplitude : bound on the absolute value of the result (metres).
    largest_m : wavelength of the first octave.
    persistence : amplitude ratio between successive octaves.
    roughness : optional array in [0, 1] of the raster's shape; octave k is scaled by
        ``(0.25 + 0.75 roughness) ** (k / n_octaves)`` (fine detail fades on low
        ground such as valley floors: a heterogeneous multi-fractal).
    rng : seed or generator.
    """
    rng = np.random.default_rng(rng)
    out = np.zeros(shape, np.float32)
    n_oct = max(int(np.floor(np.log2(max(largest_m / (2.0 * res), 1.0)))) + 1, 1)
    amp = 1.0
    base = None if roughness is None else 0.25 + 0.75 * np.clip(roughness, 0.0, 1.0)  # once, not per octave
    for k in range(n_oct):
        wave = largest_m / 2.0**k
        o = _octave(shape, max(wave / res, 1.0), rng) * amp
        if base is not None:
            o *= np.power(base, k / n_oct).astype(np.float32)
        out += o
        amp *= persistence
    peak = float(np.max(np.abs(out))) if out.size else 0.0
    if peak > 0:
        out *= np.float32(amplitude / peak)
    return out


def falloff(r: np.ndarray) -> np.ndarray:
    """Compactly supported smooth fall-off ``g(r) = (1 - r^2)^3`` on [0, 1], 0 beyond."""
    r = np.clip(np.asarray(r, dtype=np.float32), 0.0, 1.0)
    return (1.0 - r * r) ** 3


def _highpass(k: np.ndarray, largest_m: float) -> np.ndarray:
    return 1.0 - np.exp(-(k * float(largest_m)) ** 4)


def remove_plane(z: np.ndarray) -> np.ndarray:
    """``z`` (finite) minus its least-squares plane ``a x + b y + c`` (x, y in cells), as float64.

    >>> yy, xx = np.mgrid[0:4, 0:5]
    >>> float(np.abs(remove_plane(2.0 * xx - yy + 7.0)).max()) < 1e-9
    True
    """
    z = np.asarray(z, dtype=np.float64)
    ny, nx = z.shape
    yy, xx = np.mgrid[0:ny, 0:nx]
    a = np.column_stack([xx.ravel(), yy.ravel(), np.ones(z.size)])
    coef, *_ = np.linalg.lstsq(a, z.ravel(), rcond=None)
    return z - (a @ coef).reshape(z.shape)


def texture_spectrum(z: np.ndarray, res: float, *, largest_m: float = 1000.0,
                     fit_m: tuple[float, float] = (250.0, 1000.0)) -> tuple[float, float]:
    """``(rms, beta)`` of a DEM's texture: what :func:`spectral_noise` makes.

    ``rms``: root-mean-square (metres) of the DEM high-passed by the same filter as
    :func:`spectral_noise` (wavelengths below ``largest_m``), after removing a plane and
    mirroring the grid so its edges make no jump; ``beta``: spectral slope of the
    radially averaged power over wavelengths ``fit_m`` (3.0 when the grid is too small).
    NaN cells count as the mean.

    >>> n = spectral_noise((256, 256), 30.0, rms=8.0, beta=4.0, rng=1)
    >>> rms, beta = texture_spectrum(n, 30.0)
    >>> 6.0 < rms < 10.0, 3.0 < beta < 5.0
    (True, True)
    """
    z = np.asarray(z, dtype=np.float64)
    ok = np.isfinite(z)
    if ok.sum() < 16:
        return 0.0, 3.0
    z = np.where(ok, z, z[ok].mean())
    z = remove_plane(z)
    ny, nx = z.shape
    m = np.block([[z, z[:, ::-1]], [z[::-1, :], z[::-1, ::-1]]])
    ky = np.fft.fftfreq(m.shape[0], res)
    kx = np.fft.rfftfreq(m.shape[1], res)
    k = np.hypot(ky[:, None], kx[None, :])
    f = np.fft.rfft2(m)
    hp = np.fft.irfft2(f * _highpass(k, largest_m), s=m.shape)[:ny, :nx]
    rms = float(np.sqrt(np.mean(hp**2)))
    power = np.abs(f) ** 2
    kmin, kmax = 1.0 / fit_m[1], min(1.0 / fit_m[0], 0.5 / res)
    sel = (k >= kmin) & (k <= kmax)
    beta = 3.0
    if kmax > kmin * 1.5 and sel.sum() > 8:
        edges = np.geomspace(kmin, kmax, 9)
        idx = np.clip(np.searchsorted(edges, k[sel], side="right") - 1, 0, 7)
        cnt = np.bincount(idx, minlength=8)
        ps = np.bincount(idx, weights=power[sel], minlength=8)
        ks = np.bincount(idx, weights=k[sel], minlength=8)
        has = (cnt > 0) & (ps > 0)
        if has.sum() >= 3:
            beta = float(-np.polyfit(np.log10(ks[has] / cnt[has]), np.log10(ps[has] / cnt[has]), 1)[0])
    return rms, beta


def spectral_noise(shape: tuple[int, int], res: float, *, rms: float, beta: float = 3.0,
                   largest_m: float = 1000.0, rng: SeedLike = None) -> np.ndarray:
    """Gaussian noise with power spectrum ``P(k) ~ k^-beta`` at wavelengths below ``largest_m``.

    White Gaussian noise is shaped in the Fourier domain (numpy FFT, periodic) by
    ``k^(-beta/2)`` times a smooth high-pass ``1 - exp(-(k / k0)^4)`` with ``k0 = 1 / largest_m``,
    then scaled to the root-mean-square ``rms`` (metres). This is the short-wavelength
    texture of real DEMs (gullies, spurs, knobs) that the skeleton and the erosion do not
    make; a plain fractal of the whole band would also move the ridges and saddles.

    >>> n = spectral_noise((64, 64), 30.0, rms=5.0, rng=0)
    >>> n.shape, round(float(n.std()), 6), abs(float(n.mean())) < 1.0
    ((64, 64), 5.0, True)
    """
    rng = np.random.default_rng(rng)
    ny, nx = shape
    if rms <= 0 or ny < 2 or nx < 2:
        return np.zeros(shape, np.float32)
    white = rng.standard_normal(shape, dtype=np.float32)  # float32 throughout: half the memory and time
    ky = np.fft.fftfreq(ny, res).astype(np.float32)
    kx = np.fft.rfftfreq(nx, res).astype(np.float32)
    k = np.hypot(ky[:, None], kx[None, :])
    k[0, 0] = np.inf
    filt = k ** np.float32(-0.5 * float(beta)) * _highpass(k, largest_m).astype(np.float32)
    filt[0, 0] = 0.0
    del k
    f = np.fft.rfft2(white)
    del white
    f *= filt
    del filt
    out = np.fft.irfft2(f, s=shape)
    out -= out.mean(dtype=np.float64)
    sd = float(out.std(dtype=np.float64))
    return (out * np.float32(rms / sd)).astype(np.float32, copy=False) if sd > 0 else np.zeros(shape, np.float32)


def power_law_fit(z: np.ndarray, res: float, *, fit_m: tuple[float, float] = (1000.0, 10_000.0),
                  n_bins: int = 8) -> tuple[float, float]:
    """``(c, beta)`` of the power spectral density ``S(k) = c k^-beta`` of ``z`` over wavelengths ``fit_m``.

    ``S(k) = |FFT|^2 res^2 / N`` (m^2 m^2; the variance of ``z`` is the sum of ``S`` over the
    wavenumber grid times ``dk^2``), on ``z`` block-averaged to cells of at most
    ``fit_m[0] / 8`` (plane removed, 2-D Hann taper, power divided by the taper's mean
    square), radially averaged in ``n_bins`` log-spaced bins. ``(0, 3)`` when fewer than 3
    bins hold a wavenumber (grid smaller than the band).

    >>> c, b = power_law_fit(spectral_noise((512, 512), 100.0, rms=50.0, beta=3.0, largest_m=1e6, rng=0), 100.0)
    >>> bool(abs(b - 3.0) < 0.2)
    True
    """
    z = np.asarray(z, dtype=np.float64)
    f = max(int(fit_m[0] / (8.0 * res)), 1)
    ny, nx = (z.shape[0] // f) * f, (z.shape[1] // f) * f
    if ny < 8 * f or nx < 8 * f:
        return 0.0, 3.0
    zc = z[:ny, :nx].reshape(ny // f, f, nx // f, f).mean(axis=(1, 3))
    zc = remove_plane(np.where(np.isfinite(zc), zc, np.nanmean(zc)))
    d = res * f
    w = np.outer(np.hanning(zc.shape[0]), np.hanning(zc.shape[1]))
    power = np.abs(np.fft.rfft2(zc * w)) ** 2 * d * d / zc.size / float(np.mean(w * w))
    k = np.hypot(np.fft.fftfreq(zc.shape[0], d)[:, None], np.fft.rfftfreq(zc.shape[1], d)[None, :])
    kb, pb = radial_bins(k, power, (1.0 / fit_m[1], 1.0 / fit_m[0]), n_bins)
    if len(kb) < 3:
        return 0.0, 3.0
    slope, icpt = np.polyfit(np.log(kb), np.log(pb), 1)
    return float(np.exp(icpt)), float(-slope)


def radial_bins(k: np.ndarray, power: np.ndarray, band: tuple[float, float], n_bins: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """Mean wavenumber and mean power of the ``n_bins`` log-spaced bins of ``band = (kmin, kmax)``
    that hold a wavenumber with positive summed power (empty bins left out)."""
    kmin, kmax = band
    sel = (k >= kmin) & (k <= kmax)
    edges = np.geomspace(kmin, kmax, n_bins + 1)
    idx = np.clip(np.searchsorted(edges, k[sel], side="right") - 1, 0, n_bins - 1)
    cnt = np.bincount(idx, minlength=n_bins)
    ps = np.bincount(idx, weights=power[sel], minlength=n_bins)
    ks = np.bincount(idx, weights=k[sel], minlength=n_bins)
    has = (cnt > 0) & (ps > 0)
    return ks[has] / cnt[has], ps[has] / cnt[has]


def _radial_density(z: np.ndarray, res: float, k: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Radially averaged power spectral density ``|FFT|^2 res^2 / N`` of ``z`` (plane removed,
    2-D Hann taper against the leakage of the edges' jump, power divided by its mean square) in
    the wavenumber bins ``edges``; NaN for an empty bin."""
    wy, wx = np.hanning(z.shape[0]).astype(np.float32), np.hanning(z.shape[1]).astype(np.float32)
    zz = remove_plane(z).astype(np.float32) * wy[:, None] * wx[None, :]
    w2 = float(np.mean(wy.astype(np.float64) ** 2) * np.mean(wx.astype(np.float64) ** 2))
    p = np.abs(np.fft.rfft2(zz)) ** 2 * np.float32(res * res / zz.size / w2)
    idx = np.searchsorted(edges, k.ravel(), side="right") - 1
    ok = (idx >= 0) & (idx < edges.size - 1)
    cnt = np.bincount(idx[ok], minlength=edges.size - 1)
    ps = np.bincount(idx[ok], weights=p.ravel()[ok], minlength=edges.size - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return ps / cnt


def power_law_noise(shape: tuple[int, int], res: float, *, c: float, beta: float, largest_m: float = 1000.0,
                    minus: np.ndarray | None = None, steepen: float = 0.0, steepen_below_m: float = 400.0,
                    min_beta: float = 0.0, sharp: bool = False, rng: SeedLike = None) -> np.ndarray:
    """Gaussian noise whose power spectral density is ``c k^-beta`` (see :func:`power_law_fit`)
    at wavelengths below ``largest_m`` (smooth high-pass ``1 - exp(-(k largest_m)^4)``), 0 above.

    The continuation of a surface's own spectrum to shorter wavelengths: its amplitude is set
    by ``c`` (not renormalised), so it is the same in metres at any cell size. With ``minus``
    (a grid of ``shape``), only the deficit ``max(0, c k^-beta - S_minus(k))`` is made, ``S_minus``
    being the radially averaged density of ``minus`` in 16 log-spaced bins per decade: the
    noise adds what that surface lacks of the power law, nothing where it has enough. With
    ``steepen`` > 0 the law steepens to ``beta + steepen`` below ``steepen_below_m`` (real
    spectra roll over at hillslope scales), and never shallower than ``min_beta`` there (the
    variance of the slope, the integral of ``k^2 S`` over the plane, stays finite as cells shrink
    only for a law steeper than ``k^-4``). ``sharp``: the high-pass is ``1 - exp(-(k largest_m)^8)``,
    the complement of :func:`lowpass` (what it removes, this makes).
    """
    rng = np.random.default_rng(rng)
    ny, nx = shape
    if c <= 0 or ny < 2 or nx < 2:
        return np.zeros(shape, np.float32)
    white = rng.standard_normal(shape, dtype=np.float32)
    ky = np.fft.fftfreq(ny, res).astype(np.float32)
    kx = np.fft.rfftfreq(nx, res).astype(np.float32)
    k = np.hypot(ky[:, None], kx[None, :])
    k[0, 0] = k.max()  # any finite wavenumber: the mean's coefficient is set to 0 below (beta may be < 0)
    hp = (1.0 - _sharp_lowpass(k, largest_m)) if sharp else _highpass(k, largest_m)
    target = np.float32(c) * k ** np.float32(-float(beta)) * hp.astype(np.float32)
    del hp
    extra = max(float(steepen), float(min_beta) - float(beta), 0.0)
    if extra > 0:
        target *= np.maximum(k * np.float32(steepen_below_m), np.float32(1.0)) ** np.float32(-extra)
    target[0, 0] = 0.0
    if minus is not None:
        k[0, 0] = 0.0
        kmax = float(k.max())
        kmin = min(0.1 / float(largest_m), kmax / 2.0)
        edges = np.geomspace(kmin, kmax * 1.0001, max(int(16 * np.log10(kmax * 1.0001 / kmin)), 2) + 1)
        dens = _radial_density(np.asarray(minus, np.float64), res, k, edges)
        mid = np.sqrt(edges[1:] * edges[:-1])
        has = np.isfinite(dens)
        if has.sum() >= 2:
            sm = np.interp(np.log(np.maximum(k, kmin)), np.log(mid[has]), dens[has]).astype(np.float32)
            target = np.maximum(target - sm, np.float32(0.0))
        k[0, 0] = np.inf
    # E|FFT(white)|^2 = N; S = |F|^2 res^2 / N  ->  F = FFT(white) sqrt(S) / res
    filt = np.sqrt(target) / np.float32(res)
    del target
    filt[0, 0] = 0.0
    del k
    from scipy import fft as sfft

    f = sfft.rfft2(white, workers=-1)  # single precision (numpy's FFT is double: 4 x the time)
    del white
    f *= filt
    del filt
    return sfft.irfft2(f, s=shape, workers=-1).astype(np.float32, copy=False)


def _sharp_lowpass(k: np.ndarray, largest_m: float) -> np.ndarray:
    """``exp(-(k largest_m)^8)``: 1 at long wavelengths, ~0.37 at ``largest_m``, 0 below."""
    return np.exp(-(k * np.float32(largest_m)) ** 8)


def lowpass(z: np.ndarray, res: float, largest_m: float) -> np.ndarray:
    """``z`` without its wavelengths below ``largest_m`` (Fourier filter ``exp(-(k largest_m)^8)``).

    The grid is mirrored by ``2 largest_m`` on every side first, so its edges make no jump
    (the filter acts within ~``largest_m``); float32.

    >>> y, x = np.mgrid[0:64, 0:64] * 10.0
    >>> long, short = np.sin(2 * np.pi * x / 640.0), np.sin(2 * np.pi * y / 40.0)
    >>> bool(np.abs(lowpass(long + short, 10.0, 100.0) - long)[20:-20, 20:-20].max() < 0.01)
    True
    """
    from scipy import fft as sfft

    z = np.asarray(z, np.float32)
    m = min(int(np.ceil(2.0 * largest_m / res)), min(z.shape) - 1)
    zp = np.pad(z, m, mode="reflect") if m > 0 else z
    sy, sx = sfft.next_fast_len(zp.shape[0], real=True), sfft.next_fast_len(zp.shape[1], real=True)
    ky = np.fft.fftfreq(sy, res).astype(np.float32)
    kx = np.fft.rfftfreq(sx, res).astype(np.float32)
    filt = _sharp_lowpass(np.hypot(ky[:, None], kx[None, :]), largest_m)
    f = sfft.rfft2(zp, s=(sy, sx), workers=-1)
    f *= filt
    out = sfft.irfft2(f, s=(sy, sx), workers=-1)[m:m + z.shape[0], m:m + z.shape[1]]
    return np.ascontiguousarray(out, dtype=np.float32)
