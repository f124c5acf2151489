"""``selector``: Hapala 2011's decision for one scene and a ray budget — build the uniform grid, sample
its per-ray time, estimate the kd-tree's build and per-ray time from the calibration (table1h's
measurements, or a quick built-in calibration of a few small scenes when they are missing), and keep
the grid (R <= R_C) or build the kd-tree (R > R_C).

    python -m experiments.run selector --scene bunny-948 --rays 1000000 [--json]
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from costmodel.select import DEFAULT_SAMPLE, GRID_FACTOR, GridcostEstimator, HapalaEstimator, Selector, records
from experiments.core.common import add_scene_args, emit_json
from experiments.hapala.table1 import measure_all, load_any
from tracer.constants import HAPALA_EPS
from tracer.errors import GridcostError

#: the built-in calibration when results/table1h is missing: small scenes, few rays (seconds)
BUILTIN = ["cornell", "boxes-44", "bunny-948", "cylinder-196", "particles-2000", "teapot"]
ESTIMATORS = {"gridcost": GridcostEstimator, "hapala": HapalaEstimator}


def add_arguments(p) -> None:
    add_scene_args(p)
    p.add_argument("--rays", type=float, required=True, help="number of rays R the application will shoot")
    p.add_argument("--kind", choices=("random", "path"), default="random",
                   help="ray kind to sample and calibrate on (default random)")
    p.add_argument("--estimator", choices=tuple(ESTIMATORS), default="gridcost",
                   help="gridcost (ours, default) or hapala (the paper's Eq 7/8)")
    p.add_argument("--sample-rays", type=int, default=DEFAULT_SAMPLE, help="rays sampled on the grid (default 1000)")
    p.add_argument("--eps", type=float, default=HAPALA_EPS)
    p.add_argument("--seed", type=int, default=0)


def calibration(ctx, out, quick: bool, log=print):
    """(records, source): table1h's raw measurements, else the built-in quick calibration (stored
    under ``out``/points, so a second call is instant)."""
    raw_path = Path(out) / "table1h" / "raw.json"
    if raw_path.exists():
        return records(json.loads(raw_path.read_text())), str(raw_path)
    cfg = {"rays": 1000, "repeats": 2, "grid_factor": GRID_FACTOR, "seed": 0, "samples": [100, 300, 1000],
           "hiers": ["kdtree"]}
    raw = measure_all(ctx, BUILTIN, cfg, log=log)
    return records(raw), f"built-in quick calibration ({len(BUILTIN)} small scenes, 1,000 rays per kind)"


def run(ctx, args, log=print) -> dict:
    from tracer.scene import load_mesh
    from tracer.timing import set_threads
    started = time.time()
    if args.rays < 0:
        raise GridcostError(f"--rays must be >= 0, got {args.rays:g}")
    set_threads(args.threads or 1)
    scene = load_mesh(args.mesh) if args.mesh else load_any(args.scene)
    cal, source = calibration(ctx, args.out, args.quick, log=log)
    sel = Selector(ESTIMATORS[args.estimator](), eps=args.eps, sample_rays=args.sample_rays, kind=args.kind,
                   seed=args.seed).fit(cal)
    out = sel.decide(scene, args.rays)
    out.update({"kind": args.kind, "calibration": source, "calibration_scenes": sel.n_calib_,
                "seconds": round(time.time() - started, 3)})
    return out


def main(ctx, args) -> int:
    res = run(ctx, args, log=(lambda *a: None) if args.json else print)
    if args.json:
        inf = res["rc_est"] == float("inf")
        emit_json({**res, "rc_est": None if inf else res["rc_est"], "rc_est_infinite": inf})
        return 0
    rc = res["rc_est"]
    rc_s = "∞ (the grid is faster per ray)" if rc == float("inf") else f"{rc:,.0f} rays"
    print(f"scene {res['scene']} (N = {res['N']:,}), R = {res['n_rays']:,.0f} {res['kind']} rays")
    print(f"  grid build T_B^G = {res['t_build_grid'] * 1e3:.2f} ms (measured), "
          f"t_R^G = {res['t_grid'] * 1e6:.3f} us/ray (estimated from {args.sample_rays:,} sampled rays, which took "
          f"{res['t_grid_sampled'] * 1e6:.3f} us/ray)")
    print(f"  kd-tree estimate: T_B^H = {res['t_build_hier'] * 1e3:.2f} ms, t_R^H = {res['t_hier'] * 1e6:.3f} us/ray "
          f"[{res['estimator']}; {res['calibration_scenes']} calibration scenes]")
    print(f"  R_C = {rc_s} -> step {res['step']}: use the {'uniform grid' if res['choice'] == 'grid' else res['choice']}")
    return 0
