"""benchmarks.bench_vs_mitsuba: the seed-pair estimate's standard error (one pair and pooled
pairs), the rule that extends a case's spp ladder (then pools seed pairs at its top) while its
estimate is not trustworthy, and the ladder itself on synthetic renderers (no rendering; the
smoke run is in test_benchmarks.py)."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks.bench_vs_mitsuba import (
    ExtendRule,
    Rung,
    climb,
    log_time_se,
    next_rung,
    seed_pair_estimate,
    seed_pairs_estimate,
    time_to_target,
    untrusted,
)

pytestmark = pytest.mark.lab  # tests lab code only (the `lab` marker of pyproject.toml)

MASK = np.zeros((40, 40), bool)
MASK[4:36, 4:36] = True


def _pair(rng, truth, sigma):
    return truth + rng.normal(0, sigma, truth.shape), truth + rng.normal(0, sigma, truth.shape)


def test_seed_pair_standard_error_matches_replicates():
    """The standard error of log MSE from one pair is the spread of log MSE over independent
    pairs, also when a highlight concentrates the variance in a few pixels (structure that a
    plain pixel bootstrap would count as noise: 1.4x too large here, 4x on a 256-px image); a few
    fireflies make it large while the same pair without them is precise."""
    rng = np.random.default_rng(3)
    yy, xx = np.mgrid[:40, :40]
    highlight = 1.0 + 20.0 * np.exp(-((xx - 15) ** 2 + (yy - 22) ** 2) / (2 * 2.0 ** 2))
    truth = rng.uniform(0.5, 1.5, (40, 40, 3))
    sigma = 0.05 * truth * highlight[..., None]
    reps = [seed_pair_estimate(*_pair(rng, truth, sigma), MASK) for _ in range(400)]
    log_mse = np.log([r[0] ** 2 for r in reps])
    se = np.median([r[2] for r in reps])
    assert 0.85 < se / log_mse.std(ddof=1) < 1.2, (se, log_mse.std(ddof=1))
    boot = []                                  # why not a pixel bootstrap: it counts the highlight
    for _ in range(5):
        x1, x2 = _pair(rng, truth, sigma)
        v = ((x1 - x2) ** 2 / 2)[MASK].mean(axis=1)
        boot.append(np.std([np.log(v[i].mean()) for i in rng.integers(0, len(v), (200, len(v)))]))
    assert np.median(boot) > 1.25 * log_mse.std(ddof=1)
    assert np.isclose(np.mean([r[0] for r in reps]), np.sqrt(np.mean(sigma[MASK] ** 2)) / truth[MASK].mean(),
                      rtol=0.05)

    sigma = 0.05 * truth
    x1, x2 = _pair(rng, truth, sigma)
    calm = seed_pair_estimate(x1, x2, MASK)
    x1[10, 10, 0] += 30.0                     # three fireflies in one render
    x1[20, 30, 1] += 30.0
    x2[30, 12, 2] += 30.0
    fire = seed_pair_estimate(x1, x2, MASK)
    assert calm[2] < 0.05 and fire[2] > 0.4
    assert fire[0] > 10 * calm[0]
    # outside the mask a firefly changes nothing
    x1, x2 = _pair(np.random.default_rng(1), truth, sigma)
    a = seed_pair_estimate(x1, x2, MASK)
    x1[0, 0] += 1e6
    assert seed_pair_estimate(x1, x2, MASK) == a


def test_pooled_seed_pairs():
    """One pair is the one-pair estimate; k pairs pool their squared differences (the relative
    RMSE of one render, unchanged in expectation) and their standard error falls about as
    1/sqrt(k) on Gaussian noise; with fireflies in one pair the spread of the pairs' log MSE
    sets a larger standard error than the first-order one."""
    rng = np.random.default_rng(5)
    truth = rng.uniform(0.5, 1.5, (40, 40, 3))
    sigma = 0.05 * truth
    pairs = [_pair(rng, truth, sigma) for _ in range(8)]
    assert seed_pairs_estimate(pairs[:1], MASK) == seed_pair_estimate(*pairs[0], MASK)
    one = [seed_pair_estimate(*p, MASK) for p in pairs]
    pooled = seed_pairs_estimate(pairs, MASK)
    assert np.isclose(pooled[0], np.sqrt(np.mean([e[0] ** 2 for e in one])), rtol=0.02)
    assert 0.25 < pooled[2] / np.median([e[2] for e in one]) < 0.5      # 1/sqrt(8) = 0.35
    x1, x2 = (p.copy() for p in pairs[0])
    x1[10, 10, 0] += 30.0
    x2[30, 12, 2] += 30.0
    fire = seed_pairs_estimate([(x1, x2)] + pairs[1:4], MASK)
    logs = [np.log(seed_pair_estimate(*p, MASK)[0] ** 2) for p in [(x1, x2)] + pairs[1:4]]
    assert np.isclose(fire[2], np.std(logs, ddof=1) / 2) and fire[2] > 0.5


def _rs(spps, rel, se=0.01, rate=1e3):
    return [Rung(n, n / rate, e, 1.0, [], se) for n, e in zip(spps, rel, strict=True)]


def test_extension_rule_on_synthetic_ladders():
    """Each of the three tests flags a renderer on its own; a well-behaved case, a renderer
    already at the target, the cap, the budget and --no-extend stop the extension."""
    rule = ExtendRule()
    easy = {"ours": _rs([16, 64], [0.0962, 0.0332]), "mitsuba": _rs([16, 64], [0.0955, 0.033])}
    assert untrusted(easy, 0.01, rule) == []
    assert next_rung(easy, 0.01, rule, 10.0, 3.0) == (None, [], "trusted")

    # the ilm_solo_m_68 / rooitou numbers at 16-64 spp
    hard = {"ours": _rs([16, 64], [5.84, 2.54], se=0.39), "mitsuba": _rs([16, 64], [8.51, 0.716], se=0.28)}
    spp, why, status = next_rung(hard, 0.01, rule, 40.0, 25.0)
    assert (spp, status) == (256, "extend")
    assert any(w.startswith("ours rel. RMSE 2.54") for w in why)
    assert any(w.startswith("mitsuba slope -1.79") for w in why)
    assert sum("s.e. of log MSE" in w for w in why) == 2

    def only(rel, se=0.01):
        return {"ours": _rs([16, 64], rel, se=se), "mitsuba": easy["mitsuba"]}

    for case, word in ((only([0.6, 0.3]), "rel. RMSE"),            # extrapolation too long
                       (only([0.0962, 0.0332], se=0.2), "s.e."),   # estimate too noisy
                       (only([0.2, 0.02]), "slope"),               # steeper than N^-1
                       (only([0.05, 0.045]), "slope")):            # flatter than N^-1/2
        (w,) = untrusted(case, 0.01, rule)
        assert w.startswith("ours") and word in w, w
        assert next_rung(case, 0.01, rule, 10.0, 3.0)[::2] == (256, "extend")

    # a renderer below the target is interpolated: never a reason to extend
    done = {"ours": _rs([16, 64], [0.02, 0.009], se=0.5), "mitsuba": _rs([16, 64], [0.01, 0.004], se=0.5)}
    assert next_rung(done, 0.01, rule, 10.0, 3.0) == (None, [], "trusted")

    top = {k: _rs([256, 1024], [0.8, 0.6], se=0.3) for k in ("ours", "mitsuba")}
    # at the cap: seed pairs at the top spp while fewer than max_pairs and one more fits the budget
    assert next_rung(top, 0.01, rule, 10.0, 3.0)[::2] == (1024, "seeds")
    assert next_rung(top, 0.01, rule, 470.0, 25.0)[::2] == (None, "cap")          # 470 + 25 > 480
    top["ours"][-1].pairs = rule.max_pairs
    assert next_rung(top, 0.01, rule, 10.0, 3.0)[::2] == (1024, "seeds")        # mitsuba has 1 pair
    top["mitsuba"][-1].pairs = rule.max_pairs
    assert next_rung(top, 0.01, rule, 10.0, 3.0)[::2] == (None, "cap")
    top["mitsuba"][-1].pairs, top["mitsuba"][-1].rel_rmse = 1, 0.009     # below the target: renders no pair
    assert next_rung(top, 0.01, rule, 10.0, 3.0)[::2] == (None, "cap")
    assert next_rung(top, 0.01, ExtendRule(max_spp=4096), 10.0, 3.0)[::2] == (4096, "extend")
    # over the budget for 4x the spp but not for one more pair at this spp
    assert next_rung(hard, 0.01, rule, 400.0, 25.0)[::2] == (64, "seeds")          # 400 + 4 * 25 > 480
    assert next_rung(hard, 0.01, rule, 460.0, 25.0)[::2] == (None, "budget")        # 460 + 25 > 480
    assert next_rung(hard, 0.01, ExtendRule(max_pairs=1), 400.0, 25.0)[::2] == (None, "budget")
    assert next_rung(hard, 0.01, ExtendRule(enabled=False), 40.0, 25.0)[::2] == (None, "off")
    assert next_rung(hard, 0.01, ExtendRule(enabled=False), 40.0, 25.0)[1] == why


def test_time_uncertainty_propagation():
    """Extrapolated: the top rung's standard error; interpolated: the analytic derivatives of
    the log-log interpolation with respect to both bracketing rungs' log MSE."""
    rs = _rs([4, 16, 64], [0.2, 0.1, 0.05], se=0.0)
    rs[-1].mse_se = 0.3
    assert np.isclose(log_time_se(rs, 0.01), 0.3, rtol=1e-3)
    rs = [Rung(1024, 1.0, 0.02, 1.0, [], 0.1), Rung(4096, 4.0, 0.008, 1.0, [], 0.2)]
    _, how = time_to_target(rs, 0.01)
    assert how == "interpolated"
    x_lo, x_hi = 2 * np.log(0.02), 2 * np.log(0.008)
    u = (2 * np.log(0.01) - x_lo) / (x_hi - x_lo)
    span = np.log(4.0)
    d_lo, d_hi = span * (u - 1) / (x_hi - x_lo), span * -u / (x_hi - x_lo)
    assert np.isclose(log_time_se(rs, 0.01), np.hypot(d_lo * 0.1, d_hi * 0.2), rtol=1e-3)


class _Fake:
    """A renderer of a constant image with noise ~ N^-1/2 and, when ``firefly`` > 0, rare
    large samples: per pixel a Poisson(spp * firefly) count of samples worth 3000 x the mean."""

    def __init__(self, label, firefly=0.0):
        self.label, self.firefly, self.calls = label, firefly, []

    def render(self, spp, seed):
        self.calls.append((spp, seed))
        rng = np.random.default_rng(seed + (0 if self.label == "a" else 10**6))
        img = 1.0 + rng.normal(0, 0.3 / np.sqrt(spp), (40, 40, 3))
        if self.firefly:
            img += rng.poisson(spp * self.firefly, (40, 40, 1)) * 3000.0 / spp
        return img, spp * 1e-4


@pytest.mark.parametrize("enabled", [True, False])
def test_climb_extends_a_heavy_tailed_case(enabled):
    """A well-behaved pair of renderers stays on the base ladder; when one of them has rare
    large samples both climb the same extension rungs with the same seeds, interleaved, up to
    the cap (or not at all with --no-extend), and the reasons are recorded."""
    logs = []
    rule = ExtendRule(enabled=enabled)
    rungs, imgs, ext = climb([_Fake("a"), _Fake("b")], [4, 16, 64], 0.01, rule, MASK, logs.append)
    assert [r.spp for r in rungs["a"]] == [4, 16, 64] and ext["status"] == "trusted" and not ext["rungs"]
    a, b = _Fake("a", firefly=1e-5), _Fake("b")
    rungs, imgs, ext = climb([a, b], [4, 16, 64], 0.01, rule, MASK, logs.append)
    if not enabled:
        assert ext["status"] == "off" and ext["reasons"] and ext["top_spp"] == 64
        return
    assert [r.spp for r in rungs["a"]] == [r.spp for r in rungs["b"]] == [4, 16, 64, 256, 1024]
    spps = [x["spp"] for x in ext["rungs"]]
    assert spps[:2] == [256, 1024] and ext["top_spp"] == 1024
    # past the cap: seed pairs pooled at 1024 spp by the renderer still above the target (b is
    # below it at 1024 spp), up to max_pairs, new seeds each time
    seeds = [x for x in ext["rungs"] if x.get("seed_pair")]
    assert spps[2:] == [1024] * len(seeds) and len(seeds) == rule.max_pairs - 1 and ext["status"] == "cap"
    assert rungs["a"][-1].pairs == rule.max_pairs and rungs["b"][-1].pairs == 1
    assert rungs["b"][-1].rel_rmse <= 0.01 < rungs["a"][-1].rel_rmse
    assert len(rungs["a"][-1].times) == 2 * rule.max_pairs
    assert a.calls[:len(b.calls)] == b.calls               # same spp and seeds for both on the ladder
    assert a.calls[len(b.calls):] == [(1024, s) for s in range(1010, 1010 + 2 * len(seeds))]
    assert len(set(a.calls)) == len(a.calls)               # every render its own seed
    assert all(x["reasons"] and all(w.startswith("a ") for w in x["reasons"]) for x in ext["rungs"])
    assert imgs["a"][0].shape == (40, 40, 3) and len(imgs["b"]) == 2
    assert any(line.startswith("  extending to 256 spp") for line in logs)
    assert any(line.startswith("  another seed pair at 1024 spp") for line in logs)
