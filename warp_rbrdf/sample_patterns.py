"""Sample generators (Warp functions): the random numbers every estimator draws.

Sample generators are *stateless*: a sample value is a pure function of
``(pixel seed, sample index, dimension, stream)``, so an image is deterministic per (seed,
pixel, sample) whatever the tiling or thread count.

* ``PATTERN_INDEPENDENT``: hashed uniform random numbers (lowbias32 integer hash).
* ``PATTERN_STRATIFIED`` (scene default): correlated multi-jittered 2-D points (Kensler 2013,
  "Correlated Multi-Jittered Sampling"), one independently scrambled pattern per (pixel,
  dimension) ("padded" multi-jitter: each 2-D dimension is stratified, the dimensions are
  decorrelated). An spp that is not a product ``m * n`` of the pattern's grid takes that many
  distinct cells of the next full pattern, chosen at random per pixel, so each sample stays
  uniform and every estimator unbiased (:func:`cmj_2d`).
* ``PATTERN_SOBOL``: the first two Sobol dimensions, index-shuffled and Owen-scrambled by hashing
  (Burley 2020, "Practical Hash-based Owen Scrambling"), padded the same way; any power-of-two
  prefix is a (0, m, 2)-net. Measured against CMJ by ``benchmarks.bench_env_sampling`` (same
  error within a few % on the reference sphere); not a scene option.

Dimensions are 2-D: dimension 0 is the pixel jitter; each bounce then uses one dimension for the
light sample and one for the BSDF sample.

Streams. The render kernel's ``pattern`` argument (:func:`kernel_pattern`) carries, above the
pattern code, a key of the scene's sampling strategies (:func:`stream_key`) that re-scrambles every
dimension but the camera's. So one user seed gives independent light / BSDF samples for
different samplers (a 'light' and a 'mis' render with the same seed do not share their
environment samples), the same camera rays for every sampler (a delta-light-only scene renders
identically with any sampler), and common random numbers for different materials rendered with
the same sampler (the fidelity and comparison studies' paired renders rely on that).
"""
from __future__ import annotations

import inspect

import numpy as np
import warp as wp

from . import fastmath as fmath

PATTERN_STRATIFIED = 0
PATTERN_INDEPENDENT = 1
PATTERN_SOBOL = 2
PATTERN_CODES = {"stratified": PATTERN_STRATIFIED, "independent": PATTERN_INDEPENDENT,
                 "sobol": PATTERN_SOBOL}
#: the kernel's ``pattern`` argument: the code in the low 8 bits, a stream key in the 23 above
PATTERN_MASK = 0xFF
STREAM_SHIFT = 8
STREAM_KEY_MASK = (1 << 23) - 1

ONE_MINUS_EPS = 0.99999994

_HAS_INLINE = "inline" in inspect.signature(wp.func).parameters


def _noinline(f):
    """``wp.func`` never inlined (Warp 1.19's ``inline=False``): :func:`sample_2d` holds every
    pattern's code and the render kernel calls it three times per bounce; one out-of-line copy
    (its arguments are five scalars, so a call costs a few ns) cut the cold compile of the
    default scene's kernel by about 1.9 s of CPU (7.0 -> 5.2 s, ``docs/architecture.md``)."""
    return wp.func(f, inline=False) if _HAS_INLINE else wp.func(f)


# 32-bit hash constants above 2^31 (as uint32 constants so the C++ sees no int32 overflow)
_K846CA68B = wp.constant(wp.uint32(0x846CA68B))
_K9E3779B9 = wp.constant(wp.uint32(0x9E3779B9))
_KE170893D = wp.constant(wp.uint32(0xE170893D))
_K9E501CC3 = wp.constant(wp.uint32(0x9E501CC3))
_KC860A3DF = wp.constant(wp.uint32(0xC860A3DF))
_KB36534E5 = wp.constant(wp.uint32(0xB36534E5))
_K93FC4795 = wp.constant(wp.uint32(0x93FC4795))
_KDF6E307F = wp.constant(wp.uint32(0xDF6E307F))
_KA511E9B3 = wp.constant(wp.uint32(0xA511E9B3))
_KA399D265 = wp.constant(wp.uint32(0xA399D265))
_KB5297A4D = wp.constant(wp.uint32(0xB5297A4D))


@wp.func
def hash_u32(x: wp.uint32) -> wp.uint32:
    """lowbias32 integer hash (C. Wellons)."""
    x = x ^ (x >> wp.uint32(16))
    x = x * wp.uint32(0x7FEB352D)
    x = x ^ (x >> wp.uint32(15))
    x = x * _K846CA68B
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def hash3(a: wp.uint32, b: wp.uint32, c: wp.uint32) -> wp.uint32:
    return hash_u32(a ^ hash_u32(b ^ hash_u32(c + _K9E3779B9)))


@wp.func
def u32_to_unit(x: wp.uint32) -> float:
    """Uniform float in [0, 1) from the top 24 bits."""
    return float(x >> wp.uint32(8)) * (1.0 / 16777216.0)


@wp.func
def pixel_seed(seed: int, pixel: int) -> wp.uint32:
    return hash3(wp.uint32(seed), wp.uint32(pixel), wp.uint32(0x5BD1E995))


# --- Kensler's correlated multi-jittered sampling -------------------------------------------
@wp.func
def _cmj_round(i: wp.uint32, w: wp.uint32, p: wp.uint32) -> wp.uint32:
    i = i ^ p
    i = i * _KE170893D
    i = i ^ (p >> wp.uint32(16))
    i = i ^ ((i & w) >> wp.uint32(4))
    i = i ^ (p >> wp.uint32(8))
    i = i * wp.uint32(0x0929EB3F)
    i = i ^ (p >> wp.uint32(23))
    i = i ^ ((i & w) >> wp.uint32(1))
    i = i * (wp.uint32(1) | (p >> wp.uint32(27)))
    i = i * wp.uint32(0x6935FA69)
    i = i ^ ((i & w) >> wp.uint32(11))
    i = i * wp.uint32(0x74DCB303)
    i = i ^ ((i & w) >> wp.uint32(2))
    i = i * _K9E501CC3
    i = i ^ ((i & w) >> wp.uint32(2))
    i = i * _KC860A3DF
    i = i & w
    i = i ^ (i >> wp.uint32(5))
    return i


@wp.func
def cmj_permute(i: wp.uint32, l: wp.uint32, p: wp.uint32) -> wp.uint32:
    """Pseudo-random permutation of [0, l) (cycle walking)."""
    w = l - wp.uint32(1)
    w = w | (w >> wp.uint32(1))
    w = w | (w >> wp.uint32(2))
    w = w | (w >> wp.uint32(4))
    w = w | (w >> wp.uint32(8))
    w = w | (w >> wp.uint32(16))
    i = _cmj_round(i, w, p)
    while i >= l:
        i = _cmj_round(i, w, p)
    return (i + p) % l


@wp.func
def cmj_randfloat(i: wp.uint32, p: wp.uint32) -> float:
    i = i ^ p
    i = i ^ (i >> wp.uint32(17))
    i = i ^ (i >> wp.uint32(10))
    i = i * _KB36534E5
    i = i ^ (i >> wp.uint32(12))
    i = i ^ (i >> wp.uint32(21))
    i = i * _K93FC4795
    i = i ^ _KDF6E307F
    i = i ^ (i >> wp.uint32(17))
    i = i * (wp.uint32(1) | (p >> wp.uint32(18)))
    return u32_to_unit(i)


@wp.func
def cmj_2d(s: int, n_samples: int, p: wp.uint32) -> wp.vec2:
    """Sample ``s`` (0 <= s < ``n_samples``) of a CMJ pattern scrambled by ``p``.

    The pattern is an ``m`` x ``n`` grid (``m = floor(sqrt(n_samples))``, ``n = ceil(n_samples /
    m)``). When ``n_samples < m * n`` (a count that is not such a product: 5, 32, 128, 512,
    8192, ...) the ``n_samples`` samples are ``n_samples`` distinct cells of the full pattern,
    picked by a ``p``-keyed permutation of all ``m * n`` cells. Each sample is then uniform over
    the unit square (a uniformly chosen cell, uniform inside it), so every estimator stays
    unbiased. (Kensler's original permutes the sample index over ``[0, n_samples)`` only, which
    always keeps the first ``n_samples`` cells in row order: the last row and the last columns
    are under-sampled and the mean of ``x`` over a 128-sample pattern is 0.490: rendered channel
    means are then up to 4.5 % too bright under a small bright sun.) For ``n_samples = m * n``
    both are the same permutation."""
    N = wp.uint32(n_samples)
    m = wp.uint32(fmath.fmax(1, int(wp.floor(wp.sqrt(float(n_samples))))))
    n = (N + m - wp.uint32(1)) // m
    si = cmj_permute(wp.uint32(s), m * n, p * wp.uint32(0x51633E2D))
    sx = cmj_permute(si % m, m, p * _KA511E9B3)
    sy = cmj_permute(si // m, n, p * wp.uint32(0x63D83595))
    jx = cmj_randfloat(si, p * _KA399D265)
    jy = cmj_randfloat(si, p * wp.uint32(0x711AD6A5))
    fm = float(m)
    fn = float(n)
    x = (float(si % m) + (float(sy) + jx) / fn) / fm
    y = (float(si // m) + (float(sx) + jy) / fm) / fn
    return wp.vec2(fmath.fmin(x, ONE_MINUS_EPS), fmath.fmin(y, ONE_MINUS_EPS))


# --- Owen-scrambled Sobol (Burley 2020, "Practical Hash-based Owen Scrambling") --------------
@wp.func
def reverse_bits(x: wp.uint32) -> wp.uint32:
    x = ((x >> wp.uint32(1)) & wp.uint32(0x55555555)) | ((x & wp.uint32(0x55555555)) << wp.uint32(1))
    x = ((x >> wp.uint32(2)) & wp.uint32(0x33333333)) | ((x & wp.uint32(0x33333333)) << wp.uint32(2))
    x = ((x >> wp.uint32(4)) & wp.uint32(0x0F0F0F0F)) | ((x & wp.uint32(0x0F0F0F0F)) << wp.uint32(4))
    x = ((x >> wp.uint32(8)) & wp.uint32(0x00FF00FF)) | ((x & wp.uint32(0x00FF00FF)) << wp.uint32(8))
    return (x >> wp.uint32(16)) | (x << wp.uint32(16))


_K80000000 = wp.constant(wp.uint32(0x80000000))
_K3D20ADEA = wp.constant(wp.uint32(0x3D20ADEA))
_K05526C56 = wp.constant(wp.uint32(0x05526C56))
_K53A22864 = wp.constant(wp.uint32(0x53A22864))


@wp.func
def owen_scramble(x: wp.uint32, seed: wp.uint32) -> wp.uint32:
    """Nested uniform (Owen) scramble of the bits of ``x`` by a hash keyed on ``seed``: the
    Laine-Karras style permutation on the bit-reversed value (constants of N. Vegdahl 2021)."""
    x = reverse_bits(x)
    x = x ^ (x * _K3D20ADEA)
    x = x + seed
    x = x * ((seed >> wp.uint32(16)) | wp.uint32(1))
    x = x ^ (x * _K05526C56)
    x = x ^ (x * _K53A22864)
    return reverse_bits(x)


@wp.func
def sobol_dim1(i: wp.uint32) -> wp.uint32:
    """Second Sobol dimension (direction numbers v_k = v_{k-1} ^ (v_{k-1} >> 1), v_0 = 2^31)."""
    v = _K80000000
    x = wp.uint32(0)
    while i != wp.uint32(0):
        if (i & wp.uint32(1)) != wp.uint32(0):
            x = x ^ v
        i = i >> wp.uint32(1)
        v = v ^ (v >> wp.uint32(1))
    return x


@wp.func
def sobol_2d(s: int, p: wp.uint32) -> wp.vec2:
    """Sample ``s`` of the first two Sobol dimensions, index shuffled and both coordinates
    Owen-scrambled with seeds derived from ``p`` (a (0, 2)-sequence: any power-of-two prefix is a
    (0, m, 2)-net)."""
    i = owen_scramble(wp.uint32(s), hash_u32(p ^ wp.uint32(0x68BC21EB)))
    x = owen_scramble(reverse_bits(i), hash_u32(p ^ wp.uint32(0x02E5BE93)))
    y = owen_scramble(sobol_dim1(i), hash_u32(p ^ wp.uint32(0x2F4F7B1B)))
    return wp.vec2(fmath.fmin(u32_to_unit(x), ONE_MINUS_EPS), fmath.fmin(u32_to_unit(y), ONE_MINUS_EPS))


@_noinline
def sample_2d(pattern: int, pseed: wp.uint32, s: int, spp: int, dim: int) -> wp.vec2:
    """2-D sample ``dim`` of sample ``s`` (of ``spp``) in the pixel with seed ``pseed``.
    ``pattern``: :func:`kernel_pattern` (pattern code in the low bits, stream key above them;
    the key re-scrambles every dimension but the camera's, ``dim`` 0)."""
    code = pattern & PATTERN_MASK
    p = hash_u32(pseed ^ hash_u32(wp.uint32(dim) * wp.uint32(0x2545F491) + wp.uint32(1)))
    if dim > 0:
        p = hash_u32(p ^ hash_u32(wp.uint32(pattern >> STREAM_SHIFT) + _K9E3779B9))
    if code == PATTERN_STRATIFIED:
        return cmj_2d(s, spp, p)
    if code == PATTERN_SOBOL:
        return sobol_2d(s, p)
    h = hash_u32(p ^ hash_u32(wp.uint32(s) + wp.uint32(0x68E31DA4)))
    return wp.vec2(u32_to_unit(h), u32_to_unit(hash_u32(h ^ _KB5297A4D)))


# --- sample streams ---------------------------------------------------------------------------
def stream_key(combine, technique) -> int:
    """A 23-bit key of a scene's sampling strategies: ``combine`` and ``technique`` are the
    per-material registry codes (``MaterialData.combine`` / ``.technique``); the key depends on
    the *set* of (combine, technique) pairs only (not on material names, kinds or order), so the
    same strategies give the same key (deterministic: no Python ``hash``)."""
    pairs = sorted({(int(c), int(t)) for c, t in zip(np.ravel(combine), np.ravel(technique), strict=True)})
    h = 0x811C9DC5
    for c, t in pairs:   # FNV-1a over the pairs' bytes
        for byte in (c & 0xFF, (c >> 8) & 0xFF, t & 0xFF, (t >> 8) & 0xFF):
            h = ((h ^ byte) * 0x01000193) & 0xFFFFFFFF
    return (h ^ (h >> 23)) & STREAM_KEY_MASK


def kernel_pattern(pattern: str, materials) -> int:
    """The render kernel's ``pattern`` argument for the pattern named ``pattern`` and a scene
    whose materials (a ``MaterialData``: its ``combine`` and ``technique`` arrays) use the
    strategies they use: the pattern code, plus :func:`stream_key` of those strategies shifted
    above it. So the same user seed with another sampler gives independent light and BSDF samples
    (not a copy of the first render's), while the camera rays (dimension 0) stay the same, and
    different materials rendered with the same sampler keep common random numbers (paired
    comparisons rely on it)."""
    return PATTERN_CODES[pattern] | (stream_key(materials.combine, materials.technique) << STREAM_SHIFT)
