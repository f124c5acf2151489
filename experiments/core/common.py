"""Shared CLI helpers of the experiment targets: scene selection, structure parameters, JSON output."""
from __future__ import annotations

import argparse
import json
import sys

from tracer.errors import GridcostError


def add_scene_args(p, default_scene: str | None = None) -> None:
    g = p.add_mutually_exclusive_group(required=default_scene is None)
    g.add_argument("--mesh", help="path of a mesh file (OBJ, PLY, OFF, STL, GLB)")
    g.add_argument("--scene", default=default_scene, help="named scene (see tracer.scene_names())")


def add_ray_args(p, scenes: str, rays: str, repeats: str | None = None) -> None:
    """``--scenes``, ``--rays``, ``--repeats`` (None: the target's quick or full default) and ``--seed``
    of a target that measures on rays of several kinds."""
    p.add_argument("--scenes", default=None, help=scenes)
    p.add_argument("--rays", type=int, default=None, help=rays)
    p.add_argument("--repeats", type=int, default=None, help=repeats)
    p.add_argument("--seed", type=int, default=0)


def side_list(text: str) -> list[int]:
    """argparse ``type`` of a comma-separated list of image sides (pixels, 1..16384): a bad one is
    refused by the parser with one line."""
    try:
        sides = [int(s) for s in text.split(",")]
    except ValueError:
        sides = []
    if not sides or not all(1 <= s <= 16384 for s in sides):
        raise argparse.ArgumentTypeError(f"expected comma-separated image sides between 1 and 16384, got {text!r}")
    return sides


def scene_kinds(text: str) -> dict:
    """argparse ``type`` of comma-separated ``name:compact|skinny`` pairs."""
    pairs = [s.split(":") for s in text.split(",")]
    if not all(len(p) == 2 and p[0] and p[1] in ("compact", "skinny") for p in pairs):
        raise argparse.ArgumentTypeError(f"expected comma-separated name:compact|skinny pairs, got {text!r}")
    return dict(pairs)


def add_image_args(p, scenes: str, side: str | None = None, repeats: str | None = None) -> None:
    """``--scenes``, then ``--side`` (image side in pixels) and ``--repeats`` (rounds) when their help is
    given, of a target that traces camera images."""
    p.add_argument("--scenes", default=None, help=scenes)
    if side is not None:
        p.add_argument("--side", type=int, default=None, help=side)
    if repeats is not None:
        p.add_argument("--repeats", type=int, default=None, help=repeats)


def scene_from_args(args):
    from tracer.scenes.scene import load_mesh, load_scene
    return load_mesh(args.mesh) if args.mesh else load_scene(args.scene)


def parse_params(items) -> dict:
    """``key=value`` strings to a dict; values parsed as int/float/bool when they look like one."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise GridcostError(f"structure parameter {item!r} is not key=value")
        k, v = item.split("=", 1)
        low = v.lower()
        if low in ("true", "false"):
            out[k] = low == "true"
            continue
        for conv in (int, float):
            try:
                out[k] = conv(v)
                break
            except ValueError:
                pass
        else:
            out[k] = v
    return out


def missing(v) -> bool:
    """None or a float NaN (a cell a summary prints as a dash)."""
    return v is None or (isinstance(v, float) and v != v)


def dash(v, spec: str = "{}") -> str:
    """``spec.format(v)``, or "–" when ``v`` is :func:`missing`."""
    return "–" if missing(v) else spec.format(v)


def dash_int(v) -> str:
    """``v`` as an integer with thousands separators, or "–" when it is :func:`missing`."""
    return "–" if missing(v) else f"{int(v):,}"


def emit_json(obj) -> None:
    json.dump(obj, sys.stdout, indent=None, default=float)
    sys.stdout.write("\n")


def scene_list(args, quick_scenes, full_scenes) -> list[str]:
    """The scenes a target runs: ``--scenes a,b`` when given, else its quick or full default list."""
    if getattr(args, "scenes", None):
        return [n.strip() for n in args.scenes.split(",") if n.strip()]
    return list(quick_scenes if args.quick else full_scenes)


def progress(iterable, desc: str, total: int | None = None, quiet: bool = False, unit: str = "scene"):
    """A tqdm progress bar with ETA over ``iterable`` on stderr; silent under ``--json`` (``quiet``)
    and when stderr is not a terminal (or TQDM_DISABLE=1)."""
    import os

    from tqdm import tqdm
    disable = True if quiet or os.environ.get("TQDM_DISABLE") == "1" else None
    return tqdm(iterable, desc=desc, total=total, unit=unit, leave=False, disable=disable, dynamic_ncols=True)


def expected_seconds(out_dir, names, quick: bool) -> dict[str, float]:
    """Each target's wall time in the last run of the same kind (quick or full) into ``out_dir``
    (its meta.json), the median of the known ones where a target has none: the weights of the
    overall ETA of ``all``."""
    import json
    from pathlib import Path
    known = {}
    for name in names:
        try:
            meta = json.loads((Path(out_dir) / name / "meta.json").read_text())
            if bool(meta.get("quick")) == bool(quick) and float(meta["wall_seconds"]) > 0:
                known[name] = float(meta["wall_seconds"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    default = sorted(known.values())[len(known) // 2] if known else 60.0
    return {name: known.get(name, default) for name in names}


def overall_progress(weights: dict[str, float], quiet: bool = False):
    """One bar over the whole plan of ``all`` (every target, weighted by its expected seconds, so the
    ETA is in time rather than in targets), kept above the per-target bars; ``advance(name)`` after
    each target, ``close()`` at the end."""
    import os

    from tqdm import tqdm
    disable = True if quiet or os.environ.get("TQDM_DISABLE") == "1" else None
    bar = tqdm(total=round(sum(weights.values())), desc="all", unit="s", position=0, leave=True, disable=disable,
               dynamic_ncols=True, bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix} [{elapsed}<{remaining}]")

    def advance(name: str, nxt: str | None = None):
        bar.update(round(weights[name]))
        bar.set_postfix_str(f"next {nxt}" if nxt else "done")

    bar.advance, bar.start = advance, (lambda name: bar.set_postfix_str(f"running {name}"))
    return bar
