"""One measurement point: build a structure at given parameters once, and for each ray set time it
beside the scene's reference structure and count its work. Pure: everything it needs comes in its
arguments (a Dask worker calls it through :func:`experiments.core.executor.run_point`)."""
from __future__ import annotations

import socket

import numpy as np

from tracer.accel import COUNTER_NAMES, build
from tracer.measure.timing import MIN_SAMPLE_SECONDS, clock_name, time_paired

#: the drift meter every sweep point is timed beside: a one-level grid of 8N cells on the same scene
REFERENCE = ("grid", {"factor": 8.0})

#: --quick runs (CI, first contact) take shorter timing samples than MIN_SAMPLE_SECONDS
QUICK_MIN_SAMPLE = 0.002


def reference(scene):
    """The scene's reference structure (:data:`REFERENCE`)."""
    return build(scene, REFERENCE[0], **REFERENCE[1])


def measure(scene, structure: str, params: dict, rays_by_kind: dict, repeats: int = 5,
            min_sample: float = MIN_SAMPLE_SECONDS, ref=None) -> list[dict]:
    """Build once; for each ray kind time the point and the scene's reference structure
    (:data:`REFERENCE`) side by side in ``repeats`` interleaved rounds (after a warm-up), and count
    work. Rows carry the point's own median (``seconds_raw``) and its median per-round ratio to the
    reference (``ratio_to_ref``): the ratio does not drift with the machine, which on a shared VM
    changes speed by 10-30 % between points timed minutes apart (:func:`sweep` turns it back into
    seconds)."""
    import numba
    accel = build(scene, structure, **params)
    ref = ref if ref is not None else reference(scene)
    st = accel.stats()
    rows = []
    for kind, r in rays_by_kind.items():
        tp = time_paired({"p": lambda: accel.intersect(r.origins, r.directions, counters=False),
                          "r": lambda: ref.intersect(r.origins, r.directions, counters=False)},
                         rounds=repeats, repeats=1, min_sample=min_sample)
        p, q = np.asarray(tp["p"]), np.asarray(tp["r"])
        med = float(np.median(p))
        hits, cnt = accel.intersect(r.origins, r.directions, counters=True)
        mean = cnt.mean()
        rows.append({
            "scene": scene.name, "N": scene.n, "structure": structure,
            **{f"param_{k}": v for k, v in params.items()},
            "cells": st.get("cells"), "M1": st.get("M1"), "res": "x".join(str(v) for v in st.get("res", [])) or None,
            "refs": st.get("refs"), "memory_bytes": st.get("memory_bytes"), "build_s": st.get("build_s"),
            "layout": st.get("layout"),
            "ray_kind": kind, "rays": r.n, "seed": r.seed, "seconds_raw": med, "seconds_min": float(p.min()),
            "spread": float((p.max() - p.min()) / med), "ref_seconds": float(np.median(q)),
            "ratio_to_ref": float(np.median(p / q)), "clock": clock_name(), "ns_per_ray_raw": med / r.n * 1e9,
            **{k: mean[k] for k in COUNTER_NAMES},
            "hits": float((hits.tri_id >= 0).mean()),
            "threads": numba.get_num_threads(), "worker": socket.gethostname(),
        })
    return rows


