"""Ize, Shirley & Parker 2007, "Grid Creation Strategies for Efficient Ray Tracing": every value any
output prints as the paper's. Text: ``ize-shirley-parker-2007-grid-creation-strategies.md``.

The key column of each table is ours: the scene that stands in for the paper's model (the Stanford
dragon for the Happy Buddha, ``conference-room`` (a closed hall with furniture, seen from inside) for the conference room, capped cylinders for its cylinders).
"""
from __future__ import annotations

from costmodel.papers.cite import Cited, CitedTable

PAPER = "ize-shirley-parker-2007-grid-creation-strategies"

TI_OVER_TS = Cited(4, "", "Sec 2.2", "is on average 4 for the models we have tested")

TABLE2 = CitedTable(
    where="Table 2",
    caption="Table 2: The performance of M = 8N for several models.",
    key="scene",
    columns=("model", "N", "empirical_M", "theoretical_M", "penalty_pct"),
    units=("", "triangles", "cells", "cells", "%"),
    rows=(("bunny-948", "bunny", 948, 29172, 7584, 4),
          ("bunny-69k", "bunny", 69451, 645028, 555608, 2),
          ("dragon-11k", "buddha", 15536, 132848, 124288, 1),
          ("dragon-871k", "buddha", 1087716, 4873932, 8701728, 3),
          ("conference-room", "conference", 282664, 1121514, 2261312, 5)),
    lines=("bunny 948 29172 7584 4%", "69451 645028 555608 2%", "buddha 15536 132848 124288 1%",
           "1087716 4873932 8701728 3%", "conference 282664 1121514 2261312 5%"),
    checked=("N", "empirical_M", "theoretical_M", "penalty_pct"),
)

TABLE3 = CitedTable(
    where="Table 3",
    caption="Table 3: The performance of $M = 8N^{1.5}$ for a tesellated cylinder.",
    key="scene",
    columns=("N", "empirical_M", "theoretical_M", "penalty_pct"),
    units=("triangles", "cells", "cells", "%"),
    rows=(("capped-cylinder-196", 196, 16875, 21952, 0),
          ("capped-cylinder-3996", 3996, 768337, 2020822, 3),
          ("capped-cylinder-19996", 19996, 6591676, 22620629, 10)),
    lines=("cylinder 196 16875 21952 0%", "3996 768337 2020822 3%", "19996 6591676 22620629 10%"),
    checked=("N", "empirical_M", "theoretical_M", "penalty_pct"),
)

#: Sec 3.2: 8N^1.5 against 8N on the cylinders, speed-up and size ratio (scene -> (faster, larger))
SKINNY_GAIN = {
    "capped-cylinder-196": (
        Cited(1.25, "×", "Sec 3.2", "$1.25 \\times$ faster and $14 \\times$ larger for the 196 triangle cylinder"),
        Cited(14, "×", "Sec 3.2", "$1.25 \\times$ faster and $14 \\times$ larger for the 196 triangle cylinder")),
    "capped-cylinder-3996": (
        Cited(1.7, "×", "Sec 3.2", "$1.7 \\times$ faster and $63 \\times$ larger for the 3996 triangle cylinder"),
        Cited(63, "×", "Sec 3.2", "$1.7 \\times$ faster and $63 \\times$ larger for the 3996 triangle cylinder")),
    "capped-cylinder-19996": (
        Cited(2, "×", "Sec 3.2", "$2 \\times$ faster and $141 \\times$ larger for the 19996 triangle cylinder"),
        Cited(141, "×", "Sec 3.2", "$2 \\times$ faster and $141 \\times$ larger for the 19996 triangle cylinder")),
}

TABLE4 = CitedTable(
    where="Table 4",
    caption="Table 4: The performance of $M_1 = (8N)^{3/5}$ and $M_2 = 8N_2$ for several models.",
    key="scene",
    columns=("model", "N", "empirical_cells", "theoretical_cells", "penalty_pct"),
    units=("", "triangles", "cells", "cells", "%"),
    rows=(("bunny-948", "bunny", 948, 36016, 17315, 1),
          ("bunny-69k", "bunny", 69451, 1863727, 747518, 2),
          ("dragon-11k", "buddha", 15536, 132848, 215579, 1),
          ("dragon-871k", "buddha", 1087716, 7308615, 10350245, 0),
          ("conference-room", "conference", 282664, 5194622, 2832557, 1)),
    lines=("bunny 948 36016 17315 1%", "69451 1863727 747518 2%", "buddha 15536 132848 215579 1%",
           "1087716 7308615 10350245 0%", "conference 282664 5194622 2832557 1%"),
    checked=("N", "empirical_cells", "theoretical_cells", "penalty_pct"),
)

#: Sec 4.2: the two-level grid against the best one-level grid, for the full-size models only
TWO_LEVEL_GAIN = {
    "dragon-871k": Cited(2, "×", "Sec 4.2", "we get close to a $2 \\times$ speedup in rendering time for the buddha model"),
    "conference-room": Cited(2.4, "×", "Sec 4.2", "a $2.4 \\times$ speedup for the conference room"),
}

#: Sec 4.4: Eq 17's long-skinny two-level rule against the compact rule. The paper names a 1996 and a
#: 196 triangle cylinder; its Table 3 has no 1996 cylinder, so the 1.6x is read beside both larger ones.
SKINNY_TWO_LEVEL_GAIN = {
    "capped-cylinder-196": Cited(1.2, "×", "Sec 4.4", "we get a $1.6 \\times$ and a $1.2 \\times$ rendering speed "
                                 "increase for the 1996 and respectively, 196 triangle cylinders", "1.2 \\times"),
    "capped-cylinder-1996": Cited(1.6, "×", "Sec 4.4", "we get a $1.6 \\times$ and a $1.2 \\times$ rendering speed "
                                  "increase for the 1996 and respectively, 196 triangle cylinders", "1.6 \\times"),
}

#: Fig 5 caption: the (m1, m2) factors the theory predicts
FIG5_THEORY = {
    "compact": (Cited(1.5, "", "Fig 5", "(1.5,2) for the other models"), Cited(2, "", "Fig 5", "(1.5,2) for the other models")),
    "skinny": (Cited(1.6, "", "Fig 5", "the point (1.6,2) for the cylinders"), Cited(2, "", "Fig 5", "the point (1.6,2) for the cylinders")),
}

#: Sec 5: the exponents the authors found empirically for one-level grids
EMPIRICAL_EXPONENT = {
    "compact": Cited(7 / 9, "", "Sec 5", "using $M = O(N^{7/9})$ for manifold-like models with compact triangles", "7/9"),
    "skinny": Cited(4 / 3, "", "Sec 5", "$M = O(N^{4/3})$ for manifold-like models with long skinny triangles", "4/3"),
}

ALL = (TI_OVER_TS, TABLE2, TABLE3, SKINNY_GAIN, TABLE4, TWO_LEVEL_GAIN, SKINNY_TWO_LEVEL_GAIN, FIG5_THEORY,
       EMPIRICAL_EXPONENT)
