"""Rays the Wald 2006 targets share: the camera of each stand-in scene (the room seen from inside,
as the paper views its conference room) and shadow rays from a point light to the primary hits
(Sec 4.7), plus the paired timing of several structures on one ray set and the cells of the summary
tables that set a paper's number beside ours.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from experiments.core.common import dash
from tracer.scenes.rays import Rays, bounding_sphere, camera_rays
from tracer.measure.timing import paired_ratio, time_paired

#: the room (tracer.scenes.procedural.room: 30 x 20 floor, furniture up to z = 1) is viewed from inside:
#: an eye at table height near one end, looking down the room along +x and slightly down
ROOM_EYE = np.array([0.6, 10.0, 0.95])
ROOM_LOOK = np.array([1.0, 0.15, -0.12])
#: radius of the sphere the room camera frames (sets how far in front of the eye it is centred)
ROOM_VIEW_R = 4.0


def inside_view(scene, eye, look, radius):
    """``scene`` with a ``view`` sphere placed so that :func:`tracer.scenes.rays.camera_frame` (45 degree
    field of view) puts its eye at ``eye`` looking along ``look``; returns (scene, eye_dir)."""
    fwd = np.asarray(look, np.float64) / np.linalg.norm(look)
    dist = radius / np.sin(np.radians(45.0) / 2)
    return dataclasses.replace(scene, view=(np.asarray(eye, np.float64) + fwd * dist, float(radius))), tuple(-fwd)


def wald_camera(scene, side: int, k: int) -> Rays:
    """Camera rays of a side x side image in k x k tile order: the room from inside (eye among the
    tables), every other scene from outside framing its bounding sphere (the project's default)."""
    if scene.name in ("room", "conference-room"):  # the hall's inside view, as the paper's conf
        sc, eye_dir = inside_view(scene, ROOM_EYE, ROOM_LOOK, ROOM_VIEW_R)
        return camera_rays(sc, side, side, tile=k, eye_dir=eye_dir)
    return camera_rays(scene, side, side, tile=k)


def light_position(scene) -> np.ndarray:
    """The point light: above and to the side of the scene (the room: under where a ceiling would
    be, over the middle of the tables)."""
    if scene.name in ("room", "conference-room"):
        return np.array([15.0, 10.0, 2.5])
    c, r = bounding_sphere(scene)
    return c + r * np.array([0.4, -0.3, 1.2])


#: shadow rays stop this fraction of the light-to-hit distance short of the hit (its own surface)
SHADOW_EPS = 1e-4


def shadow_rays(primary: Rays, t: np.ndarray, light) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shadow rays of the primary hits (t finite), from the light (a common origin, as the paper's
    shadow packets) to each hit point, in the primary rays' order (so k x k tiles stay together):
    origins, unnormalised directions hit - light, and tmax = 1 - SHADOW_EPS (the point is occluded
    when a triangle lies strictly between the light and it)."""
    hit = np.isfinite(t)
    p = primary.origins[hit].astype(np.float64) + t[hit, None].astype(np.float64) * primary.directions[hit]
    d = p - np.asarray(light, np.float64)
    o = np.broadcast_to(np.asarray(light, np.float64), d.shape)
    return (np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32),
            np.full(len(d), 1.0 - SHADOW_EPS, np.float32))


def paired(fns: dict, rounds: int, ref: str) -> tuple[dict, dict]:
    """Time ``fns`` in interleaved rounds; returns (name -> median seconds, name -> (median, min,
    max) of the per-round speed-up over ``ref`` = time[ref] / time[name])."""
    tp = time_paired(fns, rounds=rounds, repeats=1)
    med = {k: float(np.median(v)) for k, v in tp.items()}
    return med, {k: paired_ratio(tp, ref, k) for k in tp}


def paper_cell(r, col: str, fmt: str = "{:.2f}") -> str:
    """Column ``col`` of table row ``r`` formatted with ``fmt`` ("–" where the row has none)."""
    return dash(r.get(col), fmt)


def scene_label(r) -> str:
    """A table row's scene with the paper's scene it stands in for, when it has one: "room (conf)"."""
    ps = r.get("paper_scene")
    return f"{r.scene}{f' ({ps})' if isinstance(ps, str) else ''}"
