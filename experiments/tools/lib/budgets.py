"""advise across ray budgets: each candidate's predicted time is a line in R, build + R x per-ray
time, with a band from its relative intervals. The budget ranges where each candidate is fastest
are the pieces of the lower envelope of those lines; each crossover comes with the interval of R
over which the two bands overlap (below it the first is faster even at its worst and the second at
its best, above it the reverse). Pure functions of the candidates: nothing here measures."""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

#: the budgets advise reports over when none is given: a thousand rays to ten billion
R_RANGE = (1e3, 1e10)


@dataclass(frozen=True)
class Candidate:
    """One structure's prediction: seconds to build, seconds per ray, their relative intervals
    ((lo, hi), e.g. (-0.1, 0.1)), how it was obtained and the bytes it took when built."""
    structure: str
    params: dict
    how: str
    build_s: float
    ray_s: float
    rel_build: tuple = (0.0, 0.0)
    rel_ray: tuple = (0.0, 0.0)
    memory_bytes: int | None = None

    @classmethod
    def from_dict(cls, d: dict) -> "Candidate":
        keys = cls.__dataclass_fields__
        return cls(**{k: (tuple(v) if k.startswith("rel_") else v) for k, v in d.items() if k in keys})

    def total_s(self, R) -> np.ndarray | float:
        """Predicted build + trace seconds for ``R`` rays."""
        return self.build_s + np.asarray(R, float) * self.ray_s

    def band(self, R) -> tuple:
        """(lowest, highest) predicted seconds for ``R`` rays."""
        R = np.asarray(R, float)
        return (self.build_s * (1 + self.rel_build[0]) + R * self.ray_s * (1 + self.rel_ray[0]),
                self.build_s * (1 + self.rel_build[1]) + R * self.ray_s * (1 + self.rel_ray[1]))

    def label(self) -> str:
        extra = ", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in self.params.items())
        return f"{self.structure}" + (f" ({extra})" if extra else "")


@dataclass(frozen=True)
class BudgetRange:
    """From ``r_from`` to ``r_to`` rays ``candidate`` is predicted fastest; ``cross_lo``..``cross_hi``
    is the interval of its upper crossover (where the bands of it and the next winner overlap)."""
    candidate: str
    r_from: float
    r_to: float
    cross_lo: float | None = None
    cross_hi: float | None = None


@dataclass
class Advice:
    """What :func:`experiments.api.advise` returns: the scene, the ray kind and every candidate's
    prediction (independent of R); :meth:`pick` and :meth:`ranked` answer one budget,
    :meth:`ranges` every budget."""
    scene: str
    N: int
    kind: str
    candidates: list = field(default_factory=list)
    image: int | None = None

    def ranked(self, R: float) -> list:
        """Candidates fastest first for ``R`` rays."""
        return sorted(self.candidates, key=lambda c: float(c.total_s(R)))

    def pick(self, R: float) -> Candidate:
        return self.ranked(R)[0]

    def ranges(self, r_min: float = R_RANGE[0], r_max: float = R_RANGE[1]) -> list:
        """The budget ranges where each candidate is fastest (:func:`fastest_ranges`)."""
        return fastest_ranges(self.candidates, r_min, r_max)

    def to_dict(self, r_min: float = R_RANGE[0], r_max: float = R_RANGE[1]) -> dict:
        return {"scene": self.scene, "N": self.N, "kind": self.kind, "image": self.image,
                "candidates": [asdict(c) for c in self.candidates],
                "ranges": [asdict(r) for r in self.ranges(r_min, r_max)]}


def crossover(a: Candidate, b: Candidate) -> tuple[float, float, float]:
    """(R*, lo, hi) where ``b`` (the cheaper per ray) overtakes ``a``: R* from the central lines;
    lo where ``b`` at its best first beats ``a`` at its worst, hi where ``a`` at its best last beats
    ``b`` at its worst (0 or inf when the bands never separate on that side)."""
    def meet(ba, ra, bb, rb):
        den = ra - rb
        return max(0.0, (bb - ba) / den) if den > 0 else np.inf
    (alo_b, ahi_b), (alo_r, ahi_r) = [a.build_s * (1 + x) for x in a.rel_build], [a.ray_s * (1 + x) for x in a.rel_ray]
    (blo_b, bhi_b), (blo_r, bhi_r) = [b.build_s * (1 + x) for x in b.rel_build], [b.ray_s * (1 + x) for x in b.rel_ray]
    return (meet(a.build_s, a.ray_s, b.build_s, b.ray_s),
            meet(ahi_b, ahi_r, blo_b, blo_r), meet(alo_b, alo_r, bhi_b, bhi_r))


def fastest_ranges(cands, r_min: float = R_RANGE[0], r_max: float = R_RANGE[1]) -> list:
    """The lower envelope of the candidates' central lines over [r_min, r_max]: consecutive
    :class:`BudgetRange` pieces, each with its upper crossover's interval."""
    if not cands:
        return []
    out, R = [], float(r_min)
    cur = min(cands, key=lambda c: (float(c.total_s(R)), c.ray_s))
    while True:
        nxt, best = None, None
        for c in cands:  # the first line to undercut the current winner beyond R
            if c is cur or c.ray_s >= cur.ray_s:
                continue
            r_star = crossover(cur, c)[0]
            if r_star > R and (best is None or r_star < best or (r_star == best and c.ray_s < nxt.ray_s)):
                nxt, best = c, r_star
        if nxt is None or best >= r_max:
            out.append(BudgetRange(cur.label(), R, float(r_max)))
            return out
        _, lo, hi = crossover(cur, nxt)
        out.append(BudgetRange(cur.label(), R, float(best), float(lo), float(hi)))
        cur, R = nxt, float(best)


def describe(ranges, memory: dict | None = None) -> str:
    """One sentence: "below 3e5 rays: grid; 3e5-2e8: cgt; above: bvh4" with crossover intervals."""
    if not ranges:
        return "no candidates"
    parts = []
    for i, r in enumerate(ranges):
        span = (f"below {r.r_to:.2g} rays" if i == 0 and len(ranges) > 1 else
                f"above {r.r_from:.2g}" if i == len(ranges) - 1 and len(ranges) > 1 else
                f"{r.r_from:.2g}-{r.r_to:.2g}" if len(ranges) > 1 else f"{r.r_from:.2g}-{r.r_to:.2g} rays")
        mem = f", {memory[r.candidate] / 2 ** 20:.1f} MiB" if memory and memory.get(r.candidate) else ""
        parts.append(f"{span}: {r.candidate}{mem}")
    cross = [f"{r.candidate}/{ranges[i + 1].candidate} at {r.r_to:.2g} [{r.cross_lo:.2g}..{r.cross_hi:.2g}]"
             for i, r in enumerate(ranges[:-1])]
    return "; ".join(parts) + (f" (crossovers with their intervals: {', '.join(cross)})" if cross else "")


def check_budgets(ranges, r_max: float = R_RANGE[1]) -> list[float]:
    """The budgets ``--check`` measures: a factor 3 on both sides of each crossover (or the middle
    of the range in log R when there is none)."""
    if len(ranges) <= 1:
        r = ranges[0] if ranges else BudgetRange("", R_RANGE[0], r_max)
        return [float(np.sqrt(r.r_from * r.r_to))]
    return sorted({float(x) for r in ranges[:-1] for x in (r.r_to / 3, r.r_to * 3)})
