"""What :mod:`benchmarks.bench_chart` concludes from its ladders, and how it shows them: the time
at which each representation reaches a ΔE2000 target (:func:`reach`), the winner of a case
(:func:`case_summary`), the reason a representation does not win (:func:`why_not`), the chart
(:func:`plot_cases`) and the Markdown page (:func:`markdown`).

A ladder is a list of rungs, each a dict with ``spp``, ``seconds`` (render time of one image at
that spp, set-up excluded) and ``de_mean`` (ΔE2000 mean inside the object against the truth),
ascending in spp.
"""
from __future__ import annotations

import math

import numpy as np

#: The target of the chart's summary: ΔE2000 mean inside the object against the truth.
TARGET_DE = 1.0
#: The order of the lines and columns.
ORDER = ("rgl", "measured", "projected", "rational-2d", "rational-3d", "mitsuba")


def reach(ladder: list[dict], target: float = TARGET_DE) -> dict:
    """When ``ladder`` first reaches ΔE mean <= ``target``: ``{"seconds", "spp", "how"}``.

    ``how``: ``"interpolated"`` (log ΔE linear in log seconds and in log spp between the last
    rung above the target and the first at or below it), ``"first rung"`` (the lowest rung is
    already at or below it: its time, an upper bound), or ``"never"`` (no rung reaches it:
    ``seconds`` and ``spp`` are None and ``floor`` is the lowest ΔE mean of the ladder). Rungs
    whose ΔE or time is not a positive finite number are skipped."""
    ok = [r for r in ladder if _pos(r.get("de_mean")) and _pos(r.get("seconds"))]
    for i, r in enumerate(ok):
        if r["de_mean"] <= target:
            if i == 0:
                return {"seconds": r["seconds"], "spp": r["spp"], "how": "first rung"}
            lo = ok[i - 1]
            u = (math.log(target) - math.log(lo["de_mean"])) / (math.log(r["de_mean"]) - math.log(lo["de_mean"]))
            t = math.exp(math.log(lo["seconds"]) + u * (math.log(r["seconds"]) - math.log(lo["seconds"])))
            n = math.exp(math.log(lo["spp"]) + u * (math.log(r["spp"]) - math.log(lo["spp"])))
            return {"seconds": t, "spp": n, "how": "interpolated"}
    floor = min((r["de_mean"] for r in ok), default=float("nan"))
    return {"seconds": None, "spp": None, "how": "never", "floor": floor}


def _pos(x) -> bool:
    return x is not None and math.isfinite(x) and x > 0


def case_summary(ladders: dict[str, list[dict]], target: float = TARGET_DE) -> dict:
    """``{"reach": {rep: reach(...)}, "first": rep or None, "seconds": its time, "never": [reps]}``:
    the representation whose ladder reaches ``target`` soonest (ties: the earlier in
    :data:`ORDER`); None when none does."""
    r = {k: reach(v, target) for k, v in ladders.items()}
    got = [k for k in _ordered(r) if r[k]["seconds"] is not None]
    first = min(got, key=lambda k: r[k]["seconds"]) if got else None
    return {"reach": r, "first": first, "seconds": r[first]["seconds"] if first else None,
            "never": [k for k in _ordered(r) if r[k]["seconds"] is None]}


def _ordered(d):
    return [k for k in ORDER if k in d] + [k for k in d if k not in ORDER]


def first_of_ours(case: dict) -> tuple:
    """``(representation, seconds)`` of our renderer's first to the target (Mitsuba left out)."""
    r = {k: v for k, v in case["summary"]["reach"].items() if k != "mitsuba" and v["seconds"] is not None}
    k = min(_ordered(r), key=lambda k: r[k]["seconds"], default=None)
    return k, (r[k]["seconds"] if k else None)


def shift(ladder) -> str:
    """The top rung's channel-mean ratios and ΔE mean inside / on the rim (when recorded)."""
    top = ladder[-1]
    if "mean_ratio" not in top:
        return ""
    return (f"; at {top['spp']} spp R/G/B means {'/'.join(f'{x:.3f}' for x in top['mean_ratio'])} of the truth's, "
            f"ΔE mean {top['de_inner']:.2f} inside, {top['de_rim']:.2f} on the rim")


def why_not(case: dict, rep: str = "rational-3d") -> str:
    """One sentence from the numbers of ``case`` (a case record of bench_chart) on why ``rep``
    does not reach the target first: never reached (its floor: the lowest ΔE mean, against the
    truth's own floor), or reached later than the winner, split into the samples it needs
    (noise of its estimator and its bias) and its seconds per sample."""
    s = case["summary"]
    if rep not in case["ladders"]:
        return f"no {rep} ladder ({case.get('notes', {}).get(rep, 'not rendered')})"
    if s["first"] == rep:
        return "wins"
    me = s["reach"][rep]
    if me["seconds"] is None:
        return (f"never reaches ΔE {TARGET_DE:g} on the ladder: its lowest ΔE mean is {me['floor']:.3g} "
                f"(truth's own floor {case['truth']['floor_mean']:.2g}); "
                + ("a bias of the representation (its ΔE stops falling)" if _flat(case["ladders"][rep])
                   else "still falling at the top rung (noise: more spp needed)") + shift(case["ladders"][rep]))
    w = s["first"]
    if w is None:
        return "no representation reaches the target"
    wr = s["reach"][w]
    per_me = _sec_per_spp(case["ladders"][rep])
    per_w = _sec_per_spp(case["ladders"][w])
    out = (f"{w} first ({wr['seconds']:.3g} s vs {me['seconds']:.3g} s): {rep} needs {me['spp']:.3g} spp "
           f"against {wr['spp']:.3g}, at {per_me / per_w:.2f}x {w}'s seconds per spp")
    o, _ = first_of_ours(case)
    if o not in (w, rep, None):
        ro = s["reach"][o]
        out += (f"; of ours {o} first ({ro['seconds']:.3g} s, {ro['spp']:.3g} spp, "
                f"{_sec_per_spp(case['ladders'][rep]) / _sec_per_spp(case['ladders'][o]):.2f}x its seconds per spp)")
    return out + shift(case["ladders"][rep])


def _flat(ladder) -> bool:
    """Whether the ΔE mean fell by less than 15 % over the last two rungs (a floor, not noise)."""
    ok = [r["de_mean"] for r in ladder if _pos(r.get("de_mean"))]
    return len(ok) >= 2 and ok[-1] > 0.85 * ok[-2]


def _sec_per_spp(ladder) -> float:
    top = ladder[-1]
    return top["seconds"] / top["spp"]


# --------------------------------------------------------------------------------------------
def plot_cases(cases: list[dict], path, memory_of=None) -> None:
    """One log-log panel per case (ΔE2000 mean against render seconds, one line per
    representation, the target dashed), written atomically as the PNG ``path``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fit.atomic_files import save_figure

    mats = list(dict.fromkeys(c["material"] for c in cases))
    maps = list(dict.fromkeys(c["map"] for c in cases))
    fig, axes = plt.subplots(len(mats), len(maps), figsize=(4.2 * len(maps), 3.2 * len(mats)), squeeze=False)
    colours = dict(zip(ORDER, ("black", "tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple")))
    for c in cases:
        ax = axes[mats.index(c["material"]), maps.index(c["map"])]
        for rep in _ordered(c["ladders"]):
            lad = [r for r in c["ladders"][rep] if _pos(r["de_mean"]) and _pos(r["seconds"])]
            if not lad:
                continue
            mem = c.get("memory", {}).get(rep, {}).get("device_bytes")
            label = rep + (f" ({_mib(mem)})" if mem else "")
            ax.loglog([r["seconds"] for r in lad], [r["de_mean"] for r in lad], marker="o", ms=3, lw=1.2,
                      color=colours.get(rep), label=label, ls="--" if rep == "mitsuba" else "-")
        ax.axhline(TARGET_DE, color="grey", lw=0.8, ls=":")
        ax.axhline(c["truth"]["floor_mean"], color="grey", lw=0.6, ls="-.")
        ax.set_title(f"{c['material']} / {c['map']}", fontsize=9)
        ax.set_xlabel("render seconds", fontsize=8)
        ax.set_ylabel("ΔE2000 mean vs truth", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6)
    fig.tight_layout()
    save_figure(fig, path)


def _mib(b) -> str:
    return f"{b / 2**20:.3g} MiB" if b >= 2**20 else f"{b / 1024:.3g} KiB"


def _t(x) -> str:
    return "never" if x is None else f"{x:.3g} s"


def markdown(res: dict, image: str | None = None) -> str:
    """The results page (docs/chart.md): settings, the summary table, per case the ladders, the
    memory of each representation, and which cases the rational 3-D path wins and why not."""
    a, cases = res["args"], res["cases"]
    L = ["# Error against render time, every representation", "",
         "Generated by `benchmarks/bench_chart.py` (edits are overwritten). For each shared RGL material and "
         "map, the reference sphere of `lab/mitsuba_reference.py` rendered with each representation and its "
         "best sampler (the kind's default strategy: its own importance sampling with one environment sample, "
         "power heuristic; our `stratified` pattern, Mitsuba's `multijitter`) at a ladder of spp; the error is "
         "the CIE ΔE2000 mean (and p99) over the pixels inside the sphere against the converged `rgl` render "
         "(the truth), at the truth's exposure (99th-percentile luminance → L* = 100).", "",
         f"Run: {res['date']}, {res['machine']['processor']} ({res['machine']['cpus']} CPUs), load average "
         f"{res['machine']['loadavg_start']} at the start, {res['machine']['loadavg_end']} at the end; "
         f"{res['wall_s']:.0f} s wall; Mitsuba: {res['mitsuba'].get('version') or res['mitsuba'].get('note')}.", "",
         f"Command: `{res['command']}`", "",
         f"Settings: {a['res']} px, spp ladder {a['spp_ladder']}, truth `rgl` `mis-rgl` at {a['truth_spp']} spp "
         f"(its own seed-to-seed ΔE floor per case below), {a['threads']} render threads, seeds {a['seed']} + rung "
         f"index; render time: one render call at that spp after an untimed warm-up (set-up: files, tables, "
         f"BVH, and kernel load reported apart). Fits: 2-D at 5 % (`studies/fits.py`'s cache or shipped file, "
         f"else `rbrdf-fit brdf --model 2d --tol 0.05`), 3-D by `rbrdf-fit brdf --model 3d` with every "
         f"default (`--layout select --tol 0.01`, no time limit: a fit independent of the machine's load), "
         f"cached under `results/chart/fits/` by the file's SHA-256 and the flags; a fit the command does not "
         f"write (a 2-D fit not within its tolerance) is missing from its cases, never replaced.", ""]
    if image:
        L += [f"![ΔE2000 mean against render seconds]({image})", ""]
    n = len(cases)
    wins = [c for c in cases if c["summary"]["first"] == "rational-3d"]
    L += ["## Summary", "",
          f"The rational 3-D path reaches ΔE2000 mean ≤ {TARGET_DE:g} first on **{len(wins)} of {n}** cases "
          f"(the target of the full run: 30 of 40).", ""]
    head = (["material", "map", "first to ΔE ≤ 1", "at", "first of ours", "at"]
            + [f"{k} s to ΔE ≤ 1 (floor)" for k in ORDER])
    rows = []
    for c in cases:
        s = c["summary"]
        cells = []
        for k in ORDER:
            r = s["reach"].get(k)
            if r is None:
                cells.append("–")
            elif r["seconds"] is None:
                cells.append(f"never ({r['floor']:.2f})")
            else:
                cells.append(f"{r['seconds']:.3g}" + (" ≤" if r["how"] == "first rung" else ""))
        o, ot = first_of_ours(c)
        rows.append([c["material"], c["map"], s["first"] or "none", _t(s["seconds"]), o or "none", _t(ot)] + cells)
    L += [_table(rows, head), "",
          "(“≤”: already below the target at the lowest rung, so its time is an upper bound; never: not "
          "reached on the ladder, with the lowest ΔE mean it reached.)", "",
          "### Where the rational 3-D path does not win, and why", ""]
    L += [f"- {c['material']} / {c['map']}: {why_not(c)}" for c in cases if c["summary"]["first"] != "rational-3d"]
    L += ["", overview(cases)]
    L += ["", "## Memory of each representation", "",
          "Device bytes: the arrays the renderer uploads for the material (BRDF data) and for its sampler "
          "(inverse-CDF tables), summed; file: the bytes of the file it is read from.", ""]
    rows = []
    for c in cases:
        if c["map"] != cases[0]["map"]:
            continue
        for k in _ordered(c["memory"]):
            m = c["memory"][k]
            rows.append([c["material"], k, m.get("sampler", "–"), _b(m.get("brdf_bytes")), _b(m.get("sampler_bytes")),
                         _b(m.get("file_bytes"))])
    L += [_table(rows, ["material", "representation", "sampler", "BRDF data", "sampler data", "file"]), "",
          "## Ladders", ""]
    rows = []
    for c in cases:
        for k in _ordered(c["ladders"]):
            for r in c["ladders"][k]:
                rows.append([c["material"], c["map"], k, r["spp"], f"{r['seconds']:.3g}", f"{r['de_mean']:.3g}",
                             f"{r['de_p99']:.3g}", f"{r.get('de_inner', float('nan')):.3g}",
                             f"{r.get('de_rim', float('nan')):.3g}",
                             "/".join(f"{x:.3f}" for x in r.get("mean_ratio", [])) or "–"])
    L += [_table(rows, ["material", "map", "representation", "spp", "render s", "ΔE mean", "ΔE p99",
                        "ΔE mean inside", "ΔE mean rim", "R/G/B mean ratio"]), "",
          "(rim: the outer 15 px at 256 px of the sphere's disc, scaled with the resolution, at least 4 px, as "
          "`studies/fidelity.py`'s rim band; inside: the rest of the mask; R/G/B mean ratio: the image's "
          "channel means over the truth's.)", "",
          "## Truth and set-up", ""]
    rows = [[c["material"], c["map"], c["truth"]["spp"], f"{c['truth']['floor_mean']:.3g}",
             f"{c['truth']['floor_p99']:.3g}", c["truth"]["source"]]
            + [f"{c['setup_s'].get(k, float('nan')):.2f}" for k in ORDER] for c in cases]
    L += [_table(rows, ["material", "map", "truth spp", "truth floor mean", "p99", "truth"]
                 + [f"{k} set-up s" for k in ORDER]), "",
          "(truth floor: ΔE2000 between the two halves of the truth, scaled to one full-spp image against the "
          "converged one: the error the truth itself adds to every number above.)", ""]
    notes = [f"{c['material']} / {c['map']}: {k}: {v}" for c in cases for k, v in c.get("notes", {}).items()]
    if notes:
        L += ["Notes:", ""] + [f"- {x}" for x in notes] + [""]
    L += [f"This run: {per_case_seconds(cases):.0f} s per case (median, set-up, truth and fits included). "
          "Full size on a quiet machine (every shared RGL file, both maps: 40 cases; the defaults: 128 px, "
          "spp 4 16 64 256, truth 4096 spp; a 3-D fit is 13-50 s on one core and is made once, then cached):", "",
          "    RBRDF_DATA=/work/shared/data python -m benchmarks.bench_chart --docs", ""]
    return "\n".join(L)


def overview(cases: list[dict]) -> str:
    """Wins per representation, and per representation against ``rgl`` the median ratio of its
    seconds per spp and of its ΔE mean at the top rung (its speed and its bias plus noise)."""
    wins = {}
    for c in cases:
        wins[c["summary"]["first"] or "none"] = wins.get(c["summary"]["first"] or "none", 0) + 1
    parts = [f"First to ΔE ≤ {TARGET_DE:g}: " + ", ".join(f"{k} {v}" for k, v in sorted(wins.items(),
                                                                                     key=lambda kv: -kv[1])) + "."]
    for rep in ORDER[1:]:
        sp = [_sec_per_spp(c["ladders"][rep]) / _sec_per_spp(c["ladders"]["rgl"]) for c in cases
              if rep in c["ladders"] and "rgl" in c["ladders"]]
        de = [c["ladders"][rep][-1]["de_mean"] / c["ladders"]["rgl"][-1]["de_mean"] for c in cases
              if rep in c["ladders"] and "rgl" in c["ladders"]]
        if sp:
            parts.append(f"{rep} against rgl (median over cases): {np.median(sp):.2f}x the seconds per spp, "
                         f"{np.median(de):.2f}x the ΔE mean at the top rung.")
    return " ".join(parts)


def _b(x) -> str:
    return "–" if not x else _mib(x)


def _table(rows, head) -> str:
    out = ["| " + " | ".join(map(str, head)) + " |", "| " + " | ".join("---" for _ in head) + " |"]
    out += ["| " + " | ".join(map(str, r)) + " |" for r in rows]
    return "\n".join(out)


def per_case_seconds(cases) -> float:
    return float(np.median([c["case_s"] for c in cases])) if cases else float("nan")
