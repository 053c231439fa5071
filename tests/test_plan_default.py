"""The planner's default answer is its best (issue 35, part 9): on small seeded sites, every layout of the
candidate grid is scored (exhaustive search, K = 2 and 3) and the default ``plan`` must reach the grid's
optimum before refinement; the bound it reports must hold (never below the optimum) and its gap must be
what it says; the documented imports work."""

from __future__ import annotations

import importlib
import itertools

import numpy as np
import pytest

from footprint_uq.planning import evaluate_layout, ground_samples, load_site, plan, site_from_dict  # documented
from footprint_uq.planning.layout import layout_from_configs
from footprint_uq.planning.optimise import Objective, candidate_grid, grid_bound, precompute, swap_search


def seeded_site(seed: int) -> dict:
    """A small random site: a road and a crossing of random extent, 4 poles around it, one occluder."""
    rng = np.random.default_rng(seed)
    hw, hl = rng.uniform(4, 7), rng.uniform(12, 20)
    req = rng.uniform(0.35, 0.7)
    poles = [[-hl - 2, hw + rng.uniform(1, 5)], [hl + 2, hw + rng.uniform(1, 5)], [rng.uniform(-5, 5), -hw - 3],
             [rng.uniform(-hl, hl), hw + 8]]
    return {
        "resolution_m": 1.5,
        "zones": [{"name": "road", "polygon_m": [[-hl, -hw], [hl, -hw], [hl, hw], [-hl, hw]], "max_semi_major_m": req},
                  {"name": "crossing", "polygon_m": [[-3, -hw], [3, -hw], [3, hw], [-3, hw]],
                   "max_semi_major_m": req / 2, "weight": 3}],
        "occluders": [{"name": "kiosk", "polygon_m": [[hl / 2, hw + 2], [hl / 2 + 3, hw + 2], [hl / 2 + 3, hw + 5],
                                                      [hl / 2, hw + 5]], "height_m": 4}],
        "mounts": [{"name": f"m{i}", "position_m": [float(x), float(y)], "height_m": float(rng.uniform(6, 9))}
                   for i, (x, y) in enumerate(poles)],
        "cameras": [{"name": "hd", "image_size_px": [640, 360], "budget": "basler1", "cost": 1,
                     "lenses": [{"name": "n", "focal_px": float(rng.uniform(380, 520))}]}],
        "search": {"pan_step_deg": 90, "tilts_deg": [18, 32], "heights_per_mount": 1, "max_cameras": 2},
    }


def exhaustive(site, k: int) -> tuple[float, tuple]:
    """The grid's optimum: every layout of k cameras on k different mounts, scored on every sample."""
    samples = ground_samples(site)
    cov = precompute(site, samples, candidate_grid(site))
    obj = Objective.of(site, samples)
    best, arg = -1.0, None
    for combo in itertools.combinations(range(len(cov.configs)), k):
        if len(set(cov.mount[list(combo)])) < k:
            continue
        v = obj.value([(cov.index[c], cov.info[c]) for c in combo])
        if v > best:
            best, arg = v, combo
    return best, tuple(cov.configs[c] for c in arg)


@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("k", [2, 3])
def test_default_plan_reaches_the_grid_optimum_and_its_bound_holds(seed, k):
    site = site_from_dict(seeded_site(seed))
    best, arg = exhaustive(site, k)
    assert best > 0
    r = plan(site, max_cameras=k, refine_layout=False)  # the default method, no refinement
    assert r.method.startswith("best")
    assert r.discrete_value >= best - 1e-9 * best, (seed, k, r.discrete_value, best, r.starts)
    samples = ground_samples(site)
    ev = evaluate_layout(site, samples, [(lc.camera, lc.budget) for lc in layout_from_configs(site, r.configs)])
    assert ev.value == pytest.approx(r.discrete_value, rel=1e-12)
    b = r.bound
    assert b["upper_bound_m2"] >= best * (1 - 1e-9), b  # a bound, never below the optimum
    assert b["value_m2"] == pytest.approx(r.discrete_value) and 0 <= b["gap"] < 1
    assert b["value_m2"] >= (1 - b["gap"]) * b["upper_bound_m2"] * (1 - 1e-9)
    if k == 2:
        assert b["kind"] == "milp (proven optimum)" and b["gap"] < 1e-3, b
    # with the refinement: never below the grid's optimum
    rr = plan(site, max_cameras=k, max_refine_evals=20, seed=seed)
    assert rr.value >= best - 1e-9 * best and rr.value >= rr.discrete_value


def test_greedy_alone_can_miss_the_optimum_that_the_default_finds():
    """The issue's finding, kept as a check that the default is more than greedy: on some seeded site greedy's
    layout scores below the grid optimum, while the default reaches it."""
    for seed in range(1, 9):
        site = site_from_dict(seeded_site(seed))
        best, _ = exhaustive(site, 2)
        g = plan(site, method="greedy", max_cameras=2, refine_layout=False).discrete_value
        if g < best - 1e-9 * best:
            assert plan(site, max_cameras=2, refine_layout=False).discrete_value >= best - 1e-9 * best
            return
    pytest.skip("greedy found the optimum on every seeded site tried")


def test_lp_bound_holds_without_fusion_and_under_a_cost_limit():
    site = site_from_dict(seeded_site(4))
    samples = ground_samples(site)
    cov = precompute(site, samples, candidate_grid(site))
    for fusion, max_cost in ((False, None), (True, 2.0), (True, None)):
        obj = Objective.of(site, samples, fusion=fusion)
        best = max(obj.value([(cov.index[c], cov.info[c]) for c in combo])
                   for combo in itertools.combinations(range(len(cov.configs)), 2)
                   if len(set(cov.mount[list(combo)])) == 2 and (max_cost is None or cov.cost[list(combo)].sum()
                                                                 <= max_cost))
        ub = grid_bound(cov, obj, 2, max_cost)
        assert ub >= best * (1 - 1e-9), (fusion, max_cost, ub, best)


def test_swap_search_never_worsens_and_fills_free_slots():
    site = site_from_dict(seeded_site(5))
    samples = ground_samples(site)
    cov = precompute(site, samples, candidate_grid(site))
    obj = Objective.of(site, samples)
    rng = np.random.default_rng(0)
    best, _ = exhaustive(site, 3)
    ends = []
    for _ in range(5):
        start = [int(c) for c in rng.choice(len(cov.configs), 2, replace=False)]
        if cov.mount[start[0]] == cov.mount[start[1]]:
            start = start[:1]
        v0 = obj.value([(cov.index[c], cov.info[c]) for c in start])
        picks, v = swap_search(cov, obj, start, 3)
        assert v >= v0 and len(picks) <= 3 and len(set(cov.mount[picks])) == len(picks)
        assert v == pytest.approx(obj.value([(cov.index[c], cov.info[c]) for c in picks]))
        ends.append((v0, v, len(picks)))
    assert all(n == 3 and v > v0 for v0, v, n in ends), ends  # random starts: each improved and filled
    assert sum(v >= best * (1 - 1e-9) for _, v, _ in ends) >= 3, (ends, best)  # mostly to the optimum


def test_documented_imports_work():
    import re
    from pathlib import Path

    import footprint_uq.planning as P

    doc = (Path(__file__).resolve().parents[1] / "docs" / "planning.md").read_text()
    listed = re.search(r"In Python: `footprint_uq\.planning` \(([^)]*)\)", doc).group(1)
    names = re.findall(r"`(\w+)`", listed)
    assert names and all(hasattr(P, n) for n in names), names
    lines = re.findall(r"^from footprint_uq[\w.]* import .*$", doc, flags=re.M)
    assert lines
    for line in lines:
        exec(line, {})
    dotted = set(re.findall(r"`(footprint_uq(?:\.\w+)+)`", doc))  # every dotted name the page cites
    assert len(dotted) >= 5
    for name in dotted:
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
            break
    assert callable(load_site)
