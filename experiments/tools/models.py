"""``python -m experiments.run models [--download] [--json]``: every named scene, its faces, where it was found
(path and lookup step: --models / $GRIDCOST_MODELS, ../shared/models, shipped in tracer/data, the user cache) or
that it is missing and how to get it (URL, environment variable), and its licence (see :mod:`tracer.scenes.registry`).

Files found are checked against the registry's sha256. ``--download`` fetches the missing meshes into the user
cache first (pooch; needs the network). Text mode prints a table and the notes; ``--json`` prints exactly one
JSON object ``{"scenes": [...], "lookup": [...], ...}``. Both write ``<out>/models/models.json`` and
``<out>/models/summary.md``. Exit status 1 when a file found has the wrong sha256, else 0 (missing meshes get
stand-ins when loaded, so they are not an error here).
"""
from __future__ import annotations

import json
import os
from tracer.settings import current
from tracer.storage import atomic_write


def add_arguments(parser) -> None:
    parser.add_argument("--download", action="store_true",
                        help="download the missing meshes into the user cache first (pooch, sha256-verified)")


def report(download: bool = False) -> dict:
    """Every registry mesh with where it is (verified), MANIFEST-only meshes and the procedural scenes."""
    from tracer.scenes import procedural, registry
    from tracer.scenes.scene import manifest

    downloaded = {}
    if download:
        for name in registry.MESHES:
            if not registry.candidates(name):
                found = registry.find(name, download=True)
                downloaded[name] = found.download_error or "downloaded"
    scenes = []
    for name, mesh in registry.MESHES.items():
        st = registry.status(name)
        if not st["found"]:
            st["how_to_get"] = registry.how_to_get(mesh)
        if name in downloaded:
            st["download"] = downloaded[name]
        scenes.append(st)
    extras = [{"name": n, "file": r.get("file"), "faces": int(r["faces"]) if r.get("faces") else None,
               "found": True, "step": r.get("found"), "path": r.get("path"), "licence": r.get("license", "")}
              for n, r in manifest().items() if n not in registry.MESHES]
    return {"lookup": [{"step": s, "where": registry.STEP_HELP[s]} for s in registry.STEPS],
            "env": {"GRIDCOST_MODELS": current().models,
                    "shared_models": str(registry.shared_models_dir() or "") or None,
                    "cache": str(registry.cache_root()),
                    "downloads": registry.downloads_allowed(),
                    "stand_ins": registry.stand_ins_allowed()},
            "scenes": scenes, "manifest_only": extras,
            "procedural": {"examples": procedural.names(), "fixed": list(procedural.FIXED),
                           "families": sorted(procedural.PATTERNS)}}


def _where(s: dict) -> str:
    if not s["found"]:
        return "MISSING"
    return s["step"] + ("" if s.get("ok") in (None, True) else " (SHA256 MISMATCH)")


def render_text(rep: dict) -> str:
    rows = [("scene", "faces", "found in", "path (missing: what stands in)", "licence")]
    for s in rep["scenes"]:
        rows.append((s["name"], f"{s['faces']:,}", _where(s), s["path"] if s["found"] else f"stand-in: {s['stand_in']}",
                     s["licence"].split(";")[0].split(" (")[0]))
    for s in rep["manifest_only"]:
        rows.append((s["name"], f"{s['faces']:,}" if s["faces"] else "?", s["step"] or "", s["path"] or "",
                     s["licence"]))
    widths = [max(len(r[i]) for r in rows) for i in range(4)]
    line = lambda r: "  ".join(c.ljust(w) for c, w in zip(r[:4], widths)) + "  " + r[4]  # noqa: E731
    env = rep["env"]
    n_found = sum(s["found"] for s in rep["scenes"])
    out = ["Lookup order of a named mesh (the first file found is used; its sha256 is checked):"]
    out += [f"  {i}. {d['step']:<9} {d['where']}" for i, d in enumerate(rep["lookup"], 1)]
    out += ["", f"{n_found} of {len(rep['scenes'])} named meshes found.", "",
           line(rows[0]), line(tuple("-" * w for w in widths) + ("-" * 7,))] + [line(r) for r in rows[1:]]
    out += ["", (f"$GRIDCOST_MODELS: {env['GRIDCOST_MODELS'] or '(unset)'}; ../shared/models: "
                 f"{env['shared_models'] or 'off ($GRIDCOST_SHARED_MODELS is empty)'}; "
                 f"cache: {env['cache']}; downloads {'on' if env['downloads'] else 'off (GRIDCOST_OFFLINE=1)'}; "
                 f"stand-ins {'on' if env['stand_ins'] else 'off (GRIDCOST_NO_STAND_INS=1)'}"),
            "Procedural scenes (built in code, always available): "
            + ", ".join(f"{f.replace('_', '-')}-N" for f in rep["procedural"]["families"])
            + ", " + ", ".join(rep["procedural"]["fixed"])]
    missing = [s for s in rep["scenes"] if not s["found"]]
    if missing:
        out += ["", (f"{len(missing)} missing: loading one uses a labelled stand-in (stderr says so) unless "
                     "GRIDCOST_NO_STAND_INS=1. To get them, run `python -m experiments.run models --download` "
                     "(needs the network), or put the files under $GRIDCOST_MODELS (or --models DIR):")]
        out += [f"  {s['name']}: {s['how_to_get']}" + (f" [download: {s['download']}]" if s.get("download") else "")
                for s in missing]
    bad = [s for s in rep["scenes"] if s.get("ok") is False]
    out += [f"ERROR {s['error']}" for s in bad]
    return "\n".join(out) + "\n"


def render_markdown(rep: dict) -> str:
    esc = lambda x: str(x).replace("|", "\\|")  # noqa: E731
    out = ["# models: every named mesh, where it was found, how to get it, licence", "",
           "Lookup order: " + " → ".join(f"`{d['step']}` ({esc(d['where'])})" for d in rep["lookup"]) + ".", "",
           "| scene | faces | found in | file | licence | credit | source |", "|---|---|---|---|---|---|---|"]
    for s in rep["scenes"]:
        where = _where(s) if s["found"] else f"MISSING (stand-in: {s['stand_in']})"
        out.append(f"| {s['name']} | {s['faces']:,} | {esc(where)} | `{s['file']}` | {esc(s['licence'])} | "
                   f"{esc(s['credit'])} | {' '.join(f'<{u}>' for u in s['urls'][:2])} |")
    return "\n".join(out) + "\n"


def main(ctx, args) -> int:
    rep = report(download=bool(getattr(args, "download", False)))
    outdir = os.path.join(getattr(args, "out", None) or "results", "models")
    atomic_write(os.path.join(outdir, "models.json"), json.dumps(rep, indent=2) + "\n", mode=0o644)
    atomic_write(os.path.join(outdir, "summary.md"), render_markdown(rep), mode=0o644)
    if getattr(args, "json", False):
        print(json.dumps(rep))
    else:
        print(render_text(rep), end="")
    return 1 if any(s.get("ok") is False for s in rep["scenes"]) else 0
