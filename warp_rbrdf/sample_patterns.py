"""Sample generators (Warp functions): the random numbers every estimator draws.

Sample generators are *stateless*: a sample value is a pure function of
``(pixel seed, sample index, dimension)``, so an image is deterministic per (seed, pixel, sample)
whatever the tiling or thread count.

* ``PATTERN_INDEPENDENT``: hashed uniform random numbers (lowbias32 integer hash).
* ``PATTERN_STRATIFIED``: correlated multi-jittered 2-D points (Kensler 2013, "Correlated
  Multi-Jittered Sampling"), one independently scrambled pattern per (pixel, dimension), with
  the sample index permuted so that any spp works.

Dimensions are 2-D: dimension 0 is the pixel jitter; each bounce then uses one dimension for the
light sample and one for the BSDF sample.
"""
from __future__ import annotations

import warp as wp

PATTERN_STRATIFIED = 0
PATTERN_INDEPENDENT = 1
PATTERN_CODES = {"stratified": PATTERN_STRATIFIED, "independent": PATTERN_INDEPENDENT}

ONE_MINUS_EPS = 0.99999994

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
    """Sample ``s`` of an ``n_samples`` CMJ pattern scrambled by ``p``."""
    N = wp.uint32(n_samples)
    m = wp.uint32(wp.max(1, int(wp.floor(wp.sqrt(float(n_samples))))))
    n = (N + m - wp.uint32(1)) // m
    si = cmj_permute(wp.uint32(s), N, p * wp.uint32(0x51633E2D))
    sx = cmj_permute(si % m, m, p * _KA511E9B3)
    sy = cmj_permute(si // m, n, p * wp.uint32(0x63D83595))
    jx = cmj_randfloat(si, p * _KA399D265)
    jy = cmj_randfloat(si, p * wp.uint32(0x711AD6A5))
    fm = float(m)
    fn = float(n)
    x = (float(si % m) + (float(sy) + jx) / fn) / fm
    y = (float(si // m) + (float(sx) + jy) / fm) / fn
    return wp.vec2(wp.min(x, ONE_MINUS_EPS), wp.min(y, ONE_MINUS_EPS))


@wp.func
def sample_2d(pattern: int, pseed: wp.uint32, s: int, spp: int, dim: int) -> wp.vec2:
    """2-D sample ``dim`` of sample ``s`` (of ``spp``) in the pixel with seed ``pseed``."""
    p = hash_u32(pseed ^ hash_u32(wp.uint32(dim) * wp.uint32(0x2545F491) + wp.uint32(1)))
    if pattern == PATTERN_STRATIFIED:
        return cmj_2d(s, spp, p)
    h = hash_u32(p ^ hash_u32(wp.uint32(s) + wp.uint32(0x68E31DA4)))
    return wp.vec2(u32_to_unit(h), u32_to_unit(hash_u32(h ^ _KB5297A4D)))
