from workbench.geometry.objects import load_object
from workbench.resources import bundled_objects, paper_objects

"""Table I of Wan & Harada ("Regrasp Planning using 10,000s of Grasps"), the numbers to beat."""

TABLE_I = {
    # row: (#-tri, #-fg, t-fg s, #-fp, #-fpg, t-fp s, #-tp, #-tpg, t-tpgikn s, t-tpgikh s, gsn s, gsh s, nrn, nrh)
    "TU": (1640, 84, 10.43, 6, (0, 38, 1, 18, 33, 21), 6.45, 1008, 18648, 1746.67, 1692.74, 5.51, 15.52, 1, 3),
    "PB": (2786, 1, 10.33, 2, (0, 1), 0.51, 336, 168, 4025.69, 4069.84, 0.14, 0.17, 0, 0),
    "PW": (936, 312, 5.93, 2, (77, 84), 12.38, 336, 27048, 2200.94, 2346.49, 15.82, 30.91, 0, 1),
    "PS": (13662, 157, 101.76, 3, (97, 44, 35), 9.36, 504, 29568, 16.46, 16.09, 8.62, 28.01, 2, 2),
    "PT": (18066, 202, 218.72, 4, (46, 64, 65, 47), 15.91, 672, 37296, 2680.36, 2679.52, 11.39, 25.08, 1, 3),
    "ED": (34960, 118, 700.94, 5, (106, 25, 21, 41, 44), 8.43, 840, 39816, 3186.77, 2891.07, 7.95, 28.91, 1, 1),
}

# the project's own objects and the Table I row they stand in for
BUNDLED_ROW = {"tube": "TU", "planebody": "PB", "wheel": "PW", "bracket": "PS", "tail": "PT", "drill": "ED"}


def bench_objects(which: str = "all"):
    """(label, Table I row, loaded object) for the bundled objects and the paper's objects when present."""
    import warnings


    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if which in ("all", "bundled"):
            for name, path in bundled_objects().items():
                out.append((name, BUNDLED_ROW.get(name, "-"), load_object(path)))
        if which in ("all", "paper"):
            for row, path in paper_objects().items():
                out.append((f"{row} (paper)", row, load_object(path, units="mm", name=row)))
    return out
