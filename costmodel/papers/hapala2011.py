"""Hapala, Karlik & Havran 2011, "When It Makes Sense to Use Uniform Grids for Ray Tracing": every
value any output prints as the paper's. Text: ``hapala-karlik-havran-2011-when-to-use-uniform-grids.md``.

Times are the paper's (a Core 2 Duo E4300 at 1.8 GHz, one thread, C++): build times in ms, per-ray
traversal times in microseconds. An R_C of 0 means the grid is never slower (the paper's convention).
"""
from __future__ import annotations

from costmodel.papers.cite import Cited, CitedTable

PAPER = "hapala-karlik-havran-2011-when-to-use-uniform-grids"

_CAPTION = ("Table 1: Measurements for all tested scenes for both ray generation schemes. $T_B^G$ and $T_B^H$ "
            "are uniform grid and kd-tree build times.")

TABLE1 = CitedTable(
    where="Table 1",
    caption=_CAPTION,
    columns=("scene", "N", "sigma", "T_BG_ms", "T_BH_ms", "t_RG_us_random", "t_RH_us_random", "R_C_random",
             "t_RG_us_path", "t_RH_us_path", "R_C_path"),
    units=("", "primitives", "", "ms", "ms", "us", "us", "rays", "us", "us", "rays"),
    rows=(
    ('boxes', 528, 7.46, 2, 12, 5.0, 4.1, 11669, 0.9, 1.4, 0),
    ('interior dance', 1990, 10.84, 3, 50, 5.0, 4.2, 55328, 0.7, 1.3, 0),
    ('cornell', 2450, 8.73, 3, 42, 7.9, 5.5, 15773, 3.0, 3.0, 38177),
    ('sphere', 2880, 4.85, 4, 74, 7.7, 7.9, 0, 0.6, 1.6, 0),
    ('teapot', 3080, 7.5, 32, 73, 6.8, 6.0, 78320, 0.8, 1.6, 0),
    ('interior 3', 3412, 10.75, 4, 83, 4.6, 3.8, 101888, 0.9, 1.0, 124367),
    ('phone', 7716, 15.85, 6, 207, 3.3, 2.9, 441922, 3.3, 0.9, 53984),
    ('spheres', 31460, 7.7, 22, 696, 11.2, 8.1, 211736, 2.0, 4.9, 0),
    ('pills', 32606, 12.9, 21, 802, 7.1, 3.6, 221538, 2.3, 1.8, 593553),
    ('teapots', 52360, 12.43, 29, 1215, 13.4, 6.8, 172843, 4.3, 5.4, 1620297),
    ('building', 54490, 42.19, 21, 995, 6.3, 3.1, 304414, 12.8, 1.8, 63055),
    ('knot', 56448, 6.97, 35, 1300, 20.2, 12.1, 147560, 1.3, 3.3, 0),
    ('bunny', 69473, 7.48, 35, 1639, 33.1, 10.8, 69587, 1.3, 2.5, 0),
    ('interior japan', 72310, 43.03, 36, 1241, 4.6, 4.8, 0, 3.1, 1.9, 515863),
    ('sphere-high', 87120, 6.68, 48, 1751, 23.5, 13.5, 161984, 1.1, 2.8, 0),
    ('case', 131228, 24.93, 51, 2872, 14.0, 4.2, 293541, 5.3, 3.0, 638451),
    ('hunger', 141143, 64.21, 47, 2586, 15.9, 5.6, 250041, 68.2, 3.1, 236153),
    ('interior deloix', 149090, 16.02, 67, 3928, 22.9, 6.6, 231927, 3.0, 1.9, 1704493),
    ('camel', 178102, 72.49, 73, 3734, 23.0, 6.0, 216668, 3.3, 2.5, 1734172),
    ('sockets', 187330, 15.93, 102, 5229, 22.8, 8.9, 358906, 1.2, 2.8, 0),
    ('conference', 190947, 25.62, 97, 4428, 19.4, 7.1, 348928, 2.8, 2.7, 3268361),
    ('chess', 249608, 12.65, 103, 5799, 16.4, 5.1, 543065, 1.4, 1.1, 6037314),
    ('phone-high', 318756, 30.72, 145, 8163, 6.7, 2.9, 2262962, 7.5, 1.5, 856324),
    ('pills-high', 590626, 15.23, 283, 18694, 17.7, 4.3, 1401905, 4.6, 2.9, 5082077),
    ('a10', 1070671, 60.79, 403, 29921, 25.0, 5.9, 1544378, 2.6, 3.1, 52604130),
    ('hunger-high', 1418560, 136.61, 384, 27690, 44.2, 5.6, 727590, 156.3, 3.9, 27356),
    ('case-high', 1614006, 36.86, 501, 37224, 39.6, 4.5, 1108126, 11.1, 4.5, 3101617),
    ('sockets-high', 1658432, 16.8, 730, 45842, 41.0, 11.0, 1516267, 2.7, 4.1, 0),
    ),
    lines=(
    'boxes 528 7.46 2 12 5.0 4.1 11,669 0.9 1.4 0',
    'interior dance 1,990 10.84 3 50 5.0 4.2 55,328 0.7 1.3 0',
    'cornell 2,450 8.73 3 42 7.9 5.5 15,773 3.0 3.0 38,177',
    'sphere 2,880 4.85 4 74 7.7 7.9 0 0.6 1.6 0',
    'teapot 3,080 7.50 32 73 6.8 6.0 78,320 0.8 1.6 0',
    'interior 3 3,412 10.75 4 83 4.6 3.8 101,888 0.9 1.0 124,367',
    'phone 7,716 15.85 6 207 3.3 2.9 441,922 3.3 0.9 53,984',
    'spheres 31,460 7.70 22 696 11.2 8.1 211,736 2.0 4.9 0',
    'pills 32,606 12.90 21 802 7.1 3.6 221,538 2.3 1.8 593,553',
    'teapots 52,360 12.43 29 1,215 13.4 6.8 172,843 4.3 5.4 1,620,297',
    'building 54,490 42.19 21 995 6.3 3.1 304,414 12.8 1.8 63,055',
    'knot 56,448 6.97 35 1,300 20.2 12.1 147,560 1.3 3.3 0',
    'bunny 69,473 7.48 35 1,639 33.1 10.8 69,587 1.3 2.5 0',
    'interior japan 72,310 43.03 36 1,241 4.6 4.8 0 3.1 1.9 515,863',
    'sphere-high 87,120 6.68 48 1,751 23.5 13.5 161,984 1.1 2.8 0',
    'case 131,228 24.93 51 2,872 14.0 4.2 293,541 5.3 3.0 638,451',
    'hunger 141,143 64.21 47 2,586 15.9 5.6 250,041 68.2 3.1 236,153',
    'interior deloix 149,090 16.02 67 3,928 22.9 6.6 231,927 3.0 1.9 1,704,493',
    'camel 178,102 72.49 73 3,734 23.0 6.0 216,668 3.3 2.5 1,734,172',
    'sockets 187,330 15.93 102 5,229 22.8 8.9 358,906 1.2 2.8 0',
    'conference 190,947 25.62 97 4,428 19.4 7.1 348,928 2.8 2.7 3,268,361',
    'chess 249,608 12.65 103 5,799 16.4 5.1 543,065 1.4 1.1 6,037,314',
    'phone-high 318,756 30.72 145 8,163 6.7 2.9 2,262,962 7.5 1.5 856,324',
    'pills-high 590,626 15.23 283 18,694 17.7 4.3 1,401,905 4.6 2.9 5,082,077',
    'a10 1,070,671 60.79 403 29,921 25.0 5.9 1,544,378 2.6 3.1 52,604,130',
    'hunger-high 1,418,560 136.61 384 27,690 44.2 5.6 727,590 156.3 3.9 27,356',
    'case-high 1,614,006 36.86 501 37,224 39.6 4.5 1,108,126 11.1 4.5 3,101,617',
    'sockets-high 1,658,432 16.80 730 45,842 41.0 11.0 1,516,267 2.7 4.1 0',
    ),
    checked=("N", "sigma", "T_BG_ms", "T_BH_ms", "t_RG_us_random", "t_RH_us_random", "R_C_random",
             "t_RG_us_path", "t_RH_us_path", "R_C_path"),
)

_SLOWDOWN = ("the slowdown is only 4.5% on average, with a minimum value of 2.1% (1,070,671 triangles) and a "
             "maximum value of 15.4% (528 triangles)")
#: Sec 3, Analysis: build slowdown of the combined method (the grid built first and discarded), mean/min/max
BUILD_SLOWDOWN_PCT = (Cited(4.5, "%", "Sec 3 (Analysis)", _SLOWDOWN, "4.5%"),
                      Cited(2.1, "%", "Sec 3 (Analysis)", _SLOWDOWN, "2.1%"),
                      Cited(15.4, "%", "Sec 3 (Analysis)", _SLOWDOWN, "15.4%"))
_SPEEDUP = ("The speedup reaches the average value of 28.07 with a minimum of 6.5 (528 triangles) and a maximum of "
            "46.50 (1,070,671 triangles).")
#: Sec 3, Analysis: maximum speed-up of the combined method for log2 N rays, mean/min/max
LOG_RAYS_SPEEDUP = (Cited(28.07, "×", "Sec 3 (Analysis)", _SPEEDUP),
                    Cited(6.5, "×", "Sec 3 (Analysis)", _SPEEDUP),
                    Cited(46.50, "×", "Sec 3 (Analysis)", _SPEEDUP, "46.50"))

#: Sec 4: the paper's reading of its Figs 1-2 (average relative error of the R_C estimate over 5000 splits).
#: The paper prints no percentage of correct picks or of time lost.
ESTIMATE_ERROR = {
    "random": Cited(25, "%", "Sec 4, Fig 1", "For randomly generated rays (see Figure 1) the estimate is about 25 "
                    "percent more optimistic about the quality of the grid"),
    "path": Cited(30, "%", "Sec 4, Fig 2", "For path traced rays (see Figure 2) the estimate is off by around 30 "
                  "percent"),
}
#: Sec 4: the calibration protocol
SPLITS = Cited(5000, "", "Sec 4", "we have repeated the computation 5000 times for every of these cases")
CALIBRATION_MAX = Cited(27, "scenes", "Sec 4", "This number $C$ is increased from 1 to 27")

ALL = (TABLE1, BUILD_SLOWDOWN_PCT, LOG_RAYS_SPEEDUP, ESTIMATE_ERROR, SPLITS, CALIBRATION_MAX)
