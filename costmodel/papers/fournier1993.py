"""Fournier & Poulin 1993, "A Ray Tracing Accelerator Based on a Hierarchy of 1D Sorted Lists": every
value any output prints as the paper's. Text: ``fournier-poulin-1993-hierarchy-of-1d-sorted-lists.md``.

Times are the paper's own machine's (1993); read ratios, not milliseconds.
"""
from __future__ import annotations

from costmodel.papers.cite import Cited, CitedTable

PAPER = "fournier-poulin-1993-hierarchy-of-1d-sorted-lists"

TABLE1 = CitedTable(
    where="Table 1",
    caption="Table 1: No Hierarchy",
    key="scene",
    columns=("label", "objects", "min_tests", "nogrid_ms", "list_tests", "list_events", "list_ms"),
    units=("", "objects", "per ray", "ms/ray", "per ray", "per ray", "ms/ray"),
    rows=(
          ('sphereflake-1', 'Spheres I', 11, 0.34, 0.25, 1.3, 28.2, 0.58),
          ('sphereflake-2', 'Spheres II', 92, 0.38, 1.29, 1.41, 241.7, 3.67),
          ('sphereflake-3', 'Spheres III', 821, 0.42, 10.69, 1.5, 2048.8, 29.75),
          ('tetra-1', 'Tetra I', 4, 0.32, 0.12, 2.07, 4.9, 0.27),
          ('tetra-2', 'Tetra II', 16, 0.3, 0.2, 2.72, 19.2, 0.51),
          ('tetra-3', 'Tetra III', 64, 0.29, 0.54, 3.29, 78.8, 1.41),
          ('tetra-4', 'Tetra IV', 256, 0.29, 1.9, 3.61, 322.3, 4.92),
          ('tetra-5', 'Tetra V', 1024, 0.28, 7.3, 3.77, 1315.8, 18.98),
          ('tetra-6', 'Tetra VI', 4096, 0.27, 28.8, 3.84, 5354.1, 75.58),
          ('teapot', 'Teapot', 29, 1.0, 1.67, 2.7, 119.9, 2.63),
    ),
    lines=(
           '| Spheres I | 11 | 0.34 | 0.25 | 1.30 | 28.2 | 0.58 |',
           '| Spheres II | 92 | 0.38 | 1.29 | 1.41 | 241.7 | 3.67 |',
           '| Spheres III | 821 | 0.42 | 10.69 | 1.50 | 2048.8 | 29.75 |',
           '| Tetra I | 4 | 0.32 | 0.12 | 2.07 | 4.9 | 0.27 |',
           '| Tetra II | 16 | 0.30 | 0.20 | 2.72 | 19.2 | 0.51 |',
           '| Tetra III | 64 | 0.29 | 0.54 | 3.29 | 78.8 | 1.41 |',
           '| Tetra IV | 256 | 0.29 | 1.90 | 3.61 | 322.3 | 4.92 |',
           '| Tetra V | 1024 | 0.28 | 7.30 | 3.77 | 1315.8 | 18.98 |',
           '| Tetra VI | 4096 | 0.27 | 28.80 | 3.84 | 5354.1 | 75.58 |',
           '| Teapot | 29 | 1.00 | 1.67 | 2.70 | 119.9 | 2.63 |',
    ),
    checked=("objects", "min_tests", "nogrid_ms", "list_tests", "list_events", "list_ms"),
)

_GEARS = "each occupied voxel has a maximum average of 22.8 polygons per voxel (for 31537 objects)"
_TETRA = "the maximum average number of objects per occupied voxel is 28.6 (for 65536 objects)"
_TETRA_LIST = ("Our automatic hierarchy ends out with a balanced tree with 8 levels, 4 nodes for each level with all "
               "objects in the lowest level. A ray coming from the eye would therefore have to traverse a minimum of "
               "24 events before intersecting a triangle. Unfortunately, a ray traverses in average 3 times this "
               "number of events")
_AROUND = ("grid traversal tested as much as 618 times the minimum number of intersections. List traversal tested "
           "only 4.5 times this number and this resulted in 35% of the total rendering time of a $30 \\times 30 "
           "\\times 30$ grid traversal.")
_AROUND_SIZE = "This scene is made of 25426 triangles, 4610 quadrilaterals and 636 polygons"
#: Results, about Figs 3-10 (Haines' testbed against a 30^3 grid)
TEXT = {
    "gears_objects": Cited(31537, "objects", "Results (Figs 7-8)", _GEARS),
    "gears_per_voxel": Cited(22.8, "objects/voxel", "Results (Figs 7-8)", _GEARS),
    "tetra_objects": Cited(65536, "objects", "Results (Figs 9-10)", _TETRA),
    "tetra_per_voxel": Cited(28.6, "objects/voxel", "Results (Figs 9-10)", _TETRA),
    "tetra_grid_tests": Cited(14, "tests/ray", "Results (Figs 9-10)",
                              "Up to 14 intersection tests per ray are observed for grid traversal"),
    "tetra_levels": Cited(8, "levels", "Results (Figs 9-10)", _TETRA_LIST),
    "tetra_min_events": Cited(24, "events", "Results (Figs 9-10)", _TETRA_LIST),
    "tetra_events_factor": Cited(3, "×", "Results (Figs 9-10)", _TETRA_LIST),
}
#: Results: the Around Again scene
AROUND = {
    "grid_over_min": Cited(618, "×", "Results (Around Again)", _AROUND),
    "lists_over_min": Cited(4.5, "×", "Results (Around Again)", _AROUND),
    "list_over_grid_time_pct": Cited(35, "%", "Results (Around Again)", _AROUND, "35%"),
    "triangles": Cited(25426, "", "Results (Around Again)", _AROUND_SIZE),
    "quads": Cited(4610, "", "Results (Around Again)", _AROUND_SIZE),
    "polygons": Cited(636, "", "Results (Around Again)", _AROUND_SIZE),
}

ALL = (TABLE1, TEXT, AROUND)
