"""``verify``: trace rays with a structure and with the float64 brute-force oracle; count disagreements.

Exit status 0 when every ray agrees (hit/miss, triangle id, t within 1e-5 relative; a different id
at the same t where the oracle saw several triangles is a tie, counted apart), 1 otherwise.
"""
from __future__ import annotations

import time

from experiments.core.common import add_scene_args, emit_json, parse_params, scene_from_args
from experiments.core.common import progress
from tracer.accel import build
from tracer.errors import GridcostError
from tracer.accel.oracle import compare, oracle_cached
from tracer.scenes.rays import KINDS, make_rays

#: the folder gathers one JSON and summary per variant a run: the runner keeps the earlier runs' files
#: (experiments.run drops a whole-folder target's stale ones)
KEEPS_EARLIER_FILES = True

#: the scenes ``--suite`` checks every variant on: scanned meshes, a CAD part, procedural edge cases
#: (a closed box, thin cylinders with and without caps, scattered particles) and one mesh far from the
#: origin and at two extreme scales (:mod:`tracer.scenes.derived`)
SUITE_SCENES = ("bunny-69k", "dragon-48k", "fandisk", "cornell", "cylinder-3996", "capped-cylinder-3996",
                "dragon-11k", "particles-10k", "dragon-11k-far1e5", "dragon-11k-size1e-4", "dragon-11k-size1e4")
#: bench variants ``--suite`` leaves out, and why
NOT_IN_SUITE = {"bvh4-sah-fit": "its SAH weight is measured in bench's own run; the tree is a bvh4 built "
                                "with another weight, and bvh4 is verified with pbrt's",
                "grid-fit": "its density is measured in bench's own run; the grid is the same kernel at another "
                            "cell count, and grid is verified at 4N and 8N"}


def add_arguments(p) -> None:
    add_scene_args(p, default_scene="")  # not required with --suite
    p.add_argument("--structure", default="grid", help="grid | nested | kdtree | bvh (default grid)")
    p.add_argument("--param", action="append", metavar="KEY=VALUE",
                   help="structure parameter, e.g. cells=100000, mailbox=true (repeatable)")
    p.add_argument("--rays", type=int, default=100_000, help="rays per kind (default 100000)")
    p.add_argument("--kind", default="all", choices=KINDS + ("all",), help="ray kind (default all four)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--suite", action="store_true",
                   help="every named variant of bench (experiments/tools/lib/variants.py) on the suite's scenes "
                        "(verify.SUITE_SCENES, or --scene), one JSON and summary each, and an index summary.md")


def run_verify(scene, structure: str, params: dict, kinds, n_rays: int, seed: int = 0) -> dict:
    accel = build(scene, structure, **params)
    per_kind = {}
    for kind in kinds:
        rays = make_rays(scene, kind, n_rays, seed=seed)
        hits, _ = accel.intersect(rays.origins, rays.directions, counters=False)
        ref, ties = oracle_cached(scene, rays.origins, rays.directions)
        per_kind[kind] = compare(hits, ref, ties)
    tot = {k: sum(v[k] for v in per_kind.values())
           for k in ("rays", "hits", "disagreements", "hit_miss", "t_mismatch", "id_mismatch", "ties")}
    return {"scene": scene.name, "faces": scene.n, "structure": structure, "params": params,
            "stats": {k: v for k, v in accel.stats().items() if not isinstance(v, (list, dict))},
            **tot, "kinds": per_kind}


def main(ctx, args) -> int:
    kinds = KINDS if args.kind == "all" else (args.kind,)
    if args.suite:
        return _suite(args, kinds)
    if not (args.scene or args.mesh):
        raise GridcostError("needs --scene or --mesh (or --suite)")
    if (args.scene and "," in args.scene) or "," in args.structure:  # one line each, a summary file
        rc = 0
        params = parse_params(args.param)
        for structure in args.structure.split(","):
            tag = "-".join([structure] + [f"{k}-{v}" for k, v in params.items()])  # e.g. grid-layout-index
            rc = max(rc, _many(args, kinds, structure, params, tag, args.scene.split(","))[0])
        return rc
    scene = scene_from_args(args)
    t0 = time.perf_counter()
    out = run_verify(scene, args.structure, parse_params(args.param), kinds, args.rays, args.seed)
    out["seconds"] = time.perf_counter() - t0
    if args.json:
        emit_json(out)
    else:
        print(f"{out['scene']}: {out['faces']:,} faces, structure {out['structure']} {out['params']}")
        for kind, r in out["kinds"].items():
            print(f"  {kind:12s} rays {r['rays']:>9,}  hits {r['hits']:>9,}  disagreements {r['disagreements']:>4} "
                  f"(hit/miss {r['hit_miss']}, t {r['t_mismatch']}, id {r['id_mismatch']})  ties {r['ties']}")
        print(f"total: {out['rays']:,} rays, {out['disagreements']} disagreements, {out['ties']} ties "
              f"({out['seconds']:.1f} s)")
    return 0 if out["disagreements"] == 0 else 1


def _suite(args, kinds) -> int:
    """Every bench variant but NOT_IN_SUITE on the suite's scenes; an index of the totals."""
    from pathlib import Path

    from experiments.core.store import atomic_write
    from experiments.tools.lib.variants import VARIANTS
    scenes = args.scene.split(",") if args.scene else list(SUITE_SCENES)
    rc, rows, totals = 0, [], {}
    for name, (structure, params) in VARIANTS.items():
        if name in NOT_IN_SUITE:
            continue
        code, total = _many(args, kinds, structure, params, name, scenes, emit=False)
        rc = max(rc, code)
        totals[name] = {k: total[k] for k in ("rays", "disagreements", "ties", "git_commit")}
        host = total["host"]
        rows.append(f"| [{name}](summary-{name}.md) | {structure} {params or ''} | {total['rays']:,} | "
                    f"{total['disagreements']} | {total['ties']} | `{total['git_commit']}`, {host.get('host')} "
                    f"({host.get('cpu')}), {total['finished']} |")
    lines = ["# Oracle agreement of every variant", "",
             f"`gridcost verify --suite`: each variant of `bench` traced on {len(scenes)} scenes "
             f"({', '.join(scenes)}), {args.rays:,} rays per kind ({', '.join(kinds)}; seed {args.seed}) and "
             "scene, against the float64 brute-force oracle (hit/miss, triangle id, t within 1e-5 relative; a "
             "different triangle at the same t is a tie, counted apart).", "",
             "| variant | structure, parameters | rays | disagreements | ties | commit, host, finished |",
             "|---|---|---|---|---|---|", *rows, ""]
    lines += [f"Not run: {name} ({why})." for name, why in NOT_IN_SUITE.items()]
    atomic_write(Path(args.out) / "verify" / "summary.md", "\n".join(lines) + "\n")
    if args.json:  # one object for the whole suite
        emit_json({"scenes": scenes, "variants": totals, "disagreements": sum(t["disagreements"] for t in totals.values())})
    return rc


def _many(args, kinds, structure: str, params: dict, tag: str, scenes, emit: bool = True) -> tuple[int, dict]:
    """``structure`` with ``params`` on every scene: ``verify/<tag>.json`` and ``summary-<tag>.md``."""
    from pathlib import Path

    from experiments.core.store import atomic_write, git_commit, write_json
    from tracer.scenes.scene import load_scene
    from tracer.measure.timing import host_info
    outs = []
    for name in progress(scenes, f"verify {tag}", quiet=getattr(args, "json", False)):
        t0 = time.perf_counter()
        out = run_verify(load_scene(name), structure, params, kinds, args.rays, args.seed)
        out["seconds"] = time.perf_counter() - t0
        outs.append(out)
        if not args.json:
            print(f"{tag:14s} {name:20s} faces {out['faces']:>9,}  rays {out['rays']:>9,}  disagreements {out['disagreements']}  "
                  f"ties {out['ties']}  ({out['seconds']:.0f} s)", flush=True)
    total = {"variant": tag, "structure": structure, "params": params, "rays": sum(o["rays"] for o in outs),
             "disagreements": sum(o["disagreements"] for o in outs), "ties": sum(o["ties"] for o in outs),
             "git_commit": git_commit(), "host": host_info(), "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
             "scenes": outs}
    d = Path(args.out) / "verify"
    write_json(d / f"{tag}.json", total)
    lines = [f"# Oracle agreement: {structure} {params or ''}", "",
             f"Every ray traced with `{structure}` and with the float64 brute-force oracle; ray kinds: "
             f"{', '.join(kinds)}; {args.rays:,} rays per kind and scene (seed {args.seed}); commit "
             f"{total['git_commit']} on {total['host'].get('host')} ({total['host'].get('cpu')}).", "",
             "| scene | faces | rays | hits | disagreements | ties | layout |", "|---|---|---|---|---|---|---|"]
    lines += [f"| {o['scene']} | {o['faces']:,} | {o['rays']:,} | {o['hits']:,} | {o['disagreements']} | {o['ties']} | "
              f"{o['stats'].get('layout', '–')} |" for o in outs]
    lines += ["", f"Total: {total['rays']:,} rays, {total['disagreements']} disagreements, {total['ties']} ties "
              "(a different triangle at the same t: duplicate faces, shared edges)."]
    atomic_write(d / f"summary-{tag}.md", "\n".join(lines) + "\n")
    if args.json:
        if emit:
            emit_json(total)
    else:
        print(f"total: {total['rays']:,} rays, {total['disagreements']} disagreements, {total['ties']} ties")
    return (0 if total["disagreements"] == 0 else 1), total
