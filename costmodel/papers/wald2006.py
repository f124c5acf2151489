"""Wald, Ize, Kensler, Knoll & Parker 2006, "Ray Tracing Animated Scenes using Coherent Grid
Traversal": every value any output prints as the paper's. Text: ``wald-et-al-2006-coherent-grid-traversal.md``.

Tables 3 and 4 print scenes as columns; each of our rows (one per stand-in scene) quotes the whole
printed block, whitespace-normalised. The paper's machine: a Pentium IV 3.2 GHz, one thread.
"""
from __future__ import annotations

from costmodel.papers.cite import Cited, CitedTable

PAPER = "wald-et-al-2006-coherent-grid-traversal"

TABLE1 = CitedTable(
    where="Table 1",
    caption="Table 1: Ray-triangle intersection tests (in millions) for a 4×4 kd-tree and for our 4×4 frustum-grid "
            "traversal, and the impact of mailboxing (MB) and frustum culling (FC).",
    key="scene",
    columns=("paper_scene", "tris", "tests_nn_M", "tests_yn_M", "tests_yy_M", "ratio_nn_yy", "kdtree_M"),
    units=("", "triangles", "M", "M", "M", "×", "M"),
    rows=(("bunny-69k", "ben", 78_000, 12.8, 6.0, 1.5, 8.5, 1.1),
          ("bunny-16k", "hand", 15_000, 12.5, 6.0, 0.93, 13.4, 0.85),
          ("dragon-11k", "toys", 11_000, 14.0, 8.7, 1.0, 14.0, 0.82),
          ("conference-room", "conf", 274_000, 96.0, 53.9, 6.9, 13.9, 3.7)),
    lines=("ben 78K 12.8 6.0 1.5 8.5 1.1", "hand 15K 12.5 6.0 0.93 13.4 0.85", "toys 11K 14.0 8.7 1.0 14.0 0.82",
           "conf 274K 96.0 53.9 6.9 13.9 3.7"),
    checked=("tests_nn_M", "tests_yn_M", "tests_yy_M", "ratio_nn_yy", "kdtree_M"),
)

_T3 = ("scene ben hand toys erw6 conf single-ray 1.57 1.59 1.53 0.67 0.30 8×8 packets 10.6 16.1 20.0 14.0 3.2 "
       "ratio 6.75 10.1 13.1 20.9 10.6")
TABLE3 = CitedTable(
    where="Table 3",
    caption="Table 3: Static scene performance (in frames per second) for our system; and for an optimized 3DDDA "
            "single-ray grid, using a macrocell hierarchy if advantageous. Images rendered at 1024×1024 pixels",
    key="scene",
    columns=("paper_scene", "single_fps", "packet8_fps", "ratio"),
    units=("", "fps", "fps", "×"),
    rows=(("bunny-69k", "ben", 1.57, 10.6, 6.75), ("bunny-16k", "hand", 1.59, 16.1, 10.1),
          ("dragon-11k", "toys", 1.53, 20.0, 13.1), ("cornell-sphere", "erw6", 0.67, 14.0, 20.9),
          ("conference-room", "conf", 0.30, 3.2, 10.6)),
    lines=(_T3,) * 5,
    checked=("single_fps", "packet8_fps", "ratio"),
)

_T4 = ("scene ben hand toys erw6 conf # ray-triangle intersection tests (millions) single ray 2.96 3.58 1.97 8.90 "
       "15.70 packet 4×4 1.50 0.93 1.02 1.54 6.90 packet 8×8 5.74 2.54 2.23 2.00 20.70 # visited cells (millions) "
       "single ray 24.30 19.60 7.72 33.20 167.70 packet 4×4 2.91 0.95 0.80 2.18 16.54 packet 8×8 1.37 0.36 0.32 "
       "0.58 5.84 ratio 4×4 13.10 20.74 9.65 15.23 10.13 ratio 8×8 8.35 54.90 23.9 55.7 28.70")
#: the printed cell-ratio rows are the paper's own (ben's printed 13.10 / 8.35 are not its counts' 8.35 / 17.7)
TABLE4 = CitedTable(
    where="Table 4",
    caption="Table 4: Total number of triangles intersected and cells visited (in millions) for a single ray grid; "
            "a 4×4 ; and an 8×8 packet traversal.",
    key="scene",
    columns=("paper_scene", "tests_single_M", "tests_4_M", "tests_8_M", "cells_single_M", "cells_4_M", "cells_8_M",
             "ratio_4", "ratio_8"),
    units=("", "M", "M", "M", "M", "M", "M", "×", "×"),
    rows=(("bunny-69k", "ben", 2.96, 1.50, 5.74, 24.30, 2.91, 1.37, 13.10, 8.35),
          ("bunny-16k", "hand", 3.58, 0.93, 2.54, 19.60, 0.95, 0.36, 20.74, 54.90),
          ("dragon-11k", "toys", 1.97, 1.02, 2.23, 7.72, 0.80, 0.32, 9.65, 23.9),
          ("cornell-sphere", "erw6", 8.90, 1.54, 2.00, 33.20, 2.18, 0.58, 15.23, 55.7),
          ("conference-room", "conf", 15.70, 6.90, 20.70, 167.70, 16.54, 5.84, 10.13, 28.70)),
    lines=(_T4,) * 5,
    checked=("tests_single_M", "tests_4_M", "tests_8_M", "cells_single_M", "cells_4_M", "cells_8_M", "ratio_4",
             "ratio_8"),
)

#: Table 3's resolution and Table 1's ray count: 1024 x 1024 pixels
IMAGE_SIDE = Cited(1024, "pixels", "Table 3", "Images rendered at 1024×1024 pixels", "1024×1024")
#: Fig 6: the best grid resolution factor
LAMBDA = Cited(5, "", "Sec 3, Fig 6", "achieved their best performance around $\\lambda = 5$ (Figure 6)")
#: Sec 2: macrocells
MACROCELL_GAIN_PCT = Cited(30, "%", "Sec 2", "Using macrocells yields a performance improvement of around 30%", "30%")
#: Fig 7: 8x8 against 4x4 packets
PACKET_CROSSOVER_N = Cited(250_000, "triangles", "Fig 7", "There is a crossover point around 250K triangles where "
                           "4×4 packets become more efficient than 8×8 packets", "250K")
#: Fig 8 / Sec 4.4: rebuild against trace on the 10M-triangle Thai Statue at lambda = 5
BUILD_OVER_TRACE = Cited(3, "×", "Sec 4.4, Fig 8", "the grid rebuild for $\\lambda = 5$ already takes three times "
                         "longer than tracing the rays", "three times")
#: Sec 4.5: the speed-up range Table 3 shows
PACKET_SPEEDUP_RANGE = (Cited(6, "×", "Sec 4.5", "the packetized grid ranges from 6 to 21 times faster"),
                        Cited(21, "×", "Sec 4.5", "the packetized grid ranges from 6 to 21 times faster"))

ALL = (TABLE1, TABLE3, TABLE4, IMAGE_SIDE, LAMBDA, MACROCELL_GAIN_PCT, PACKET_CROSSOVER_N, BUILD_OVER_TRACE,
       PACKET_SPEEDUP_RANGE)
