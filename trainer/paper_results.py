"""The paper's published results (Tables 1, 2 and 3 of the COLLIE paper, `shared/seed/`), as data, so that
`collie report` can print them beside ours. Mean ± std over the paper's seeds, at its budget (2×1024
networks, 10 000 epochs for Ant/HalfCheetah, 5000 for the pixel bodies), bins judged by the
reference code's corner rule. Transcribed by hand from the paper's LaTeX tables.

Keys are (env, task) → method → (mean, std). Table 1 is safe state coverage; for the tasks with
"good" states its two columns are the composite (①, +1 good +1 neutral −1 bad, which equals safe
coverage by definition) and the weighted composite (②, +2 good) coverage. Table 2 is the safe
state ratio, here as a fraction. Table 3 is the zero-shot Ant motion return, average and best
(`zero_shot_mean`, `zero_shot_best`). Table 4 is the HalfCheetah Goal task's return of a controller
over the frozen skills of the Not-Flip runs (`hierarchical_mean`; Appendix: "in HalfCheetah Not-flip
tasks"). The Safety-Gym Hazard column is left out (collie's `car` rebuilds
the scene but is not the paper's Safety-Gym).
"""

from __future__ import annotations

Cell = tuple[float, float]
Table = dict[tuple[str, str], dict[str, Cell]]

_METHODS = ("oracle", "diayn", "lsd", "metra", "ddg", "dodont", "collie")


def _columns(columns: list[tuple[str, str]], rows: dict[str, list[Cell]], scale: float = 1.0) -> Table:
    """Rows of (mean, std) per method, one entry per column, into {(env, task): {method: cell}}."""
    if set(rows) != set(_METHODS) or any(len(v) != len(columns) for v in rows.values()):
        raise ValueError("each method needs one cell per column")
    return {col: {m: (rows[m][i][0] * scale, rows[m][i][1] * scale) for m in _METHODS} for i, col in enumerate(columns)}


_T1_TOP = [
    ("ant", "north"),
    ("ant", "range"),
    ("ant", "hole"),
    ("half_cheetah", "right"),
    ("quadruped", "north"),
    ("humanoid", "hole"),
]
SAFE_COVERAGE = _columns(
    _T1_TOP,
    {
        "oracle": [
            (1381.40, 150.14),
            (620.80, 35.52),
            (1295.60, 144.86),
            (97.80, 4.87),
            (112.60, 18.05),
            (75.20, 9.39),
        ],
        "diayn": [(-4.20, 0.45), (4.20, 0.45), (4.20, 0.45), (0.00, 0.00), (-4.20, 0.84), (3.60, 0.55)],
        "lsd": [(-1056.80, 515.24), (-916.80, 589.79), (933.20, 536.19), (-51.00, 11.77), (-0.60, 12.72), (4.20, 0.45)],
        "metra": [
            (-1425.80, 756.14),
            (-1247.40, 147.97),
            (1179.00, 147.26),
            (-8.40, 4.16),
            (-200.80, 77.72),
            (21.60, 10.81),
        ],
        "ddg": [(-429.20, 640.30), (-539.20, 477.69), (559.40, 443.59), (10.00, 14.85), (-59.60, 18.42), (7.00, 1.87)],
        "dodont": [
            (1307.20, 188.33),
            (-427.60, 224.09),
            (1132.20, 171.13),
            (82.80, 9.60),
            (115.20, 41.60),
            (75.80, 14.45),
        ],
        "collie": [
            (1333.20, 129.10),
            (362.20, 94.55),
            (1149.20, 127.05),
            (102.20, 4.32),
            (128.40, 44.60),
            (80.60, 25.01),
        ],
    },
)
# Table 1, lower block: Range-North ① ②, Hole-North ① ②, HalfCheetah Not-Flip.
_T1_LOW: dict[str, list[Cell]] = {
    "oracle": [(501.40, 45.77), (842.60, 44.34), (1143.00, 77.27), (1771.60, 213.72), (209.60, 14.03)],
    "diayn": [(4.20, 0.45), (4.20, 0.45), (4.20, 0.45), (4.20, 0.45), (8.80, 14.10)],
    "lsd": [(-916.80, 589.79), (-762.40, 508.72), (925.20, 463.76), (1244.20, 651.89), (71.20, 15.61)],
    "metra": [(-1247.40, 147.97), (-1095.00, 249.60), (1219.00, 133.38), (1582.00, 171.94), (187.20, 10.59)],
    "ddg": [(-583.60, 490.33), (-482.20, 432.05), (512.60, 457.37), (765.80, 664.16), (138.20, 14.45)],
    "dodont": [(-290.20, 241.79), (-10.00, 259.25), (1135.40, 294.13), (1566.60, 414.17), (195.00, 13.55)],
    "collie": [(380.40, 145.54), (622.00, 199.28), (1122.00, 190.43), (1769.80, 218.95), (215.60, 3.05)],
}
_COMPOSITE_COLS = [("ant", "range_north"), ("ant", "hole_north"), ("half_cheetah", "not_flip")]
COMPOSITE_COVERAGE = _columns(_COMPOSITE_COLS, {m: [v[0], v[2], v[4]] for m, v in _T1_LOW.items()})
WEIGHTED_COMPOSITE_COVERAGE = _columns(_COMPOSITE_COLS[:2], {m: [v[1], v[3]] for m, v in _T1_LOW.items()})
SAFE_COVERAGE |= COMPOSITE_COVERAGE  # ① equals safe coverage by definition (and Not-Flip is plain safe coverage)
COMPOSITE_COVERAGE |= {k: v for k, v in SAFE_COVERAGE.items() if k not in COMPOSITE_COVERAGE}

SAFE_RATIO = _columns(
    [*_T1_TOP, ("ant", "range_north"), ("ant", "hole_north"), ("half_cheetah", "not_flip")],
    {
        "oracle": [
            (92.60, 1.60),
            (94.30, 2.00),
            (98.90, 0.70),
            (99.00, 0.00),
            (79.80, 2.90),
            (91.20, 5.30),
            (95.80, 1.50),
            (98.60, 0.30),
            (100.00, 0.00),
        ],
        "diayn": [
            (0.00, 0.00),
            (0.00, 0.00),
            (100.00, 0.00),
            (50.00, 0.00),
            (6.20, 8.50),
            (100.00, 0.00),
            (0.00, 0.00),
            (100.00, 0.00),
            (75.20, 14.00),
        ],
        "lsd": [
            (18.30, 10.90),
            (36.40, 26.10),
            (69.00, 13.50),
            (28.50, 4.20),
            (20.60, 24.20),
            (100.00, 0.00),
            (36.40, 26.10),
            (74.50, 1.50),
            (76.10, 5.80),
        ],
        "metra": [
            (20.40, 14.70),
            (23.90, 2.10),
            (74.70, 2.20),
            (48.00, 1.00),
            (21.10, 10.60),
            (82.30, 15.40),
            (23.90, 2.10),
            (75.60, 2.50),
            (89.20, 3.20),
        ],
        "ddg": [
            (20.10, 16.80),
            (28.10, 8.80),
            (73.90, 9.40),
            (52.70, 3.30),
            (11.30, 14.30),
            (100.00, 0.00),
            (40.20, 33.50),
            (76.90, 16.40),
            (100.00, 0.00),
        ],
        "dodont": [
            (93.40, 4.70),
            (36.70, 5.70),
            (83.20, 4.50),
            (86.70, 5.30),
            (76.00, 8.00),
            (84.20, 4.30),
            (41.30, 6.20),
            (83.90, 5.00),
            (91.70, 2.80),
        ],
        "collie": [
            (96.90, 2.50),
            (80.90, 7.80),
            (90.60, 2.40),
            (98.70, 0.50),
            (87.60, 7.50),
            (90.50, 9.80),
            (81.40, 8.50),
            (93.10, 4.80),
            (100.00, 0.00),
        ],
    },
    scale=0.01,
)

# Table 3: zero-shot Ant motion, the average and the best return over the sampled skills.
_T3 = [("ant", "hole"), ("ant", "north"), ("ant", "range")]
_T3_ROWS: dict[str, list[tuple[Cell, Cell]]] = {  # per task: (average, best)
    "oracle": [
        ((938.23, 201.76), (1165.42, 89.36)),
        ((1111.08, 257.30), (1521.60, 91.41)),
        ((-595.66, 801.53), (717.70, 28.89)),
    ],
    "diayn": [
        ((209.85, 5.78), (243.62, 17.53)),
        ((-2833.11, 1539.28), (215.07, 1.37)),
        ((210.09, 5.86), (244.73, 19.49)),
    ],
    "lsd": [
        ((-34.05, 777.39), (1112.01, 386.15)),
        ((-2017.02, 1493.83), (1054.53, 467.55)),
        ((-894.28, 455.99), (474.65, 180.11)),
    ],
    "metra": [
        ((224.07, 555.11), (1193.03, 30.62)),
        ((-1897.47, 1431.75), (1249.26, 104.01)),
        ((-1149.32, 275.56), (265.29, 474.71)),
    ],
    "ddg": [
        ((43.78, 395.34), (923.51, 321.67)),
        ((-2123.80, 1078.94), (349.83, 1523.92)),
        ((-717.89, 582.27), (489.06, 111.92)),
    ],
    "dodont": [
        ((333.40, 633.35), (1155.58, 48.08)),
        ((277.15, 1519.21), (1397.12, 45.58)),
        ((-1045.95, 374.46), (540.25, 62.46)),
    ],
    "collie": [
        ((650.67, 637.03), (1251.92, 72.67)),
        ((1054.25, 376.79), (1460.44, 53.12)),
        ((-913.48, 715.64), (673.55, 65.86)),
    ],
}
ZERO_SHOT_MEAN = _columns(_T3, {m: [avg for avg, _ in v] for m, v in _T3_ROWS.items()})
ZERO_SHOT_BEST = _columns(_T3, {m: [best for _, best in v] for m, v in _T3_ROWS.items()})

HIERARCHICAL_MEAN: Table = {
    ("half_cheetah", "not_flip"): {
        "oracle": (47.46, 33.27),
        "diayn": (10.43, 4.61),
        "lsd": (32.73, 31.94),
        "metra": (21.58, 25.53),
        "ddg": (21.57, 45.27),
        "dodont": (30.44, 37.84),
        "collie": (45.26, 15.78),
    }
}

PAPER: dict[str, Table] = {
    "safe_coverage": SAFE_COVERAGE,
    "safe_ratio": SAFE_RATIO,
    "composite_coverage": COMPOSITE_COVERAGE,
    "weighted_composite_coverage": WEIGHTED_COMPOSITE_COVERAGE,
    "zero_shot_mean": ZERO_SHOT_MEAN,
    "zero_shot_best": ZERO_SHOT_BEST,
    "hierarchical_mean": HIERARCHICAL_MEAN,
}


def paper_cell(metric: str, env: str, task: str, method: str) -> Cell | None:
    """The paper's (mean, std) for one table cell, or None where it published none."""
    return PAPER.get(metric, {}).get((env, task), {}).get(method)
