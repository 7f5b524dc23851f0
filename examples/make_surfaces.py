#!/usr/bin/env python3
"""Writes the STEP-NC example parts of this folder (run from anywhere; rewrites them).

* seed-surface.stp: seed 000's test surface: 10x10 control points, p = q = 2, knots
  0,0,0,.125,...,.875,1,1,1, unit weights, over a 60 x 60 mm free-form of our own.
* torus-patch.stp: an exact rational piece of a torus (major radius 40, minor 15 mm):
  toroidal angle 0..90 deg, poloidal angle 45..135 deg (the crown), rotated and placed.
* cubic-wave.stp: p = q = 3, 8 x 8 control points, passes along v.
* tspline-bump.stp: a T-spline surface (T_SPLINE_SURFACE, the project's Part 21 form)
  with eight T-junctions, a local bump and a notch left out of its T-image, zig-zag UV
  passes in two T-regions.
* seed-surface-planecc.stp: the seed surface finished with a PLANE_CC_STRATEGY instead:
  zig-zag passes in vertical planes at 30 degrees to the x axis (normal (cos 30, sin 30, 0)
  turned by -90 degrees: the planes run at 30 degrees), chordal tolerance 1 um.
"""
import math
import os

HERE = os.path.dirname(os.path.abspath(__file__))


class Writer:
    def __init__(self):
        self.lines = []
        self.next = 1

    def add(self, text):
        n = self.next
        self.next += 1
        self.lines.append(f"#{n}={text};")
        return n

    def point(self, p):
        return self.add("CARTESIAN_POINT('',(%s))" % ",".join(fmt(x) for x in p))

    def direction(self, d):
        return self.add("DIRECTION('',(%s))" % ",".join(fmt(x) for x in d))

    def placement(self, name, origin, axis=None, ref=None):
        o = self.point(origin)
        a = f"#{self.direction(axis)}" if axis else "$"
        r = f"#{self.direction(ref)}" if ref else "$"
        return self.add(f"AXIS2_PLACEMENT_3D('{name}',#{o},{a},{r})")


def fmt(x):
    s = repr(float(x))
    if "e" in s or "E" in s:
        m, e = s.lower().split("e")
        if "." not in m:
            m += "."
        return f"{m}E{int(e)}"
    return s


def knots_of(vals):
    distinct, mult = [], []
    for k in vals:
        if distinct and distinct[-1] == k:
            mult[-1] += 1
        else:
            distinct.append(k)
            mult.append(1)
    return distinct, mult


def write(name, title, surf, tool, tech, strategy, placements):
    """surf: (p, q, pts[i][j], weights or None, knots_u, knots_v), or a function that
    writes the surface instance with a Writer and returns its number."""
    w = Writer()
    if callable(surf):
        s = surf(w)
    else:
        s = b_spline(w, title, surf)
    write_part(w, name, title, s, tool, tech, strategy, placements)


def b_spline(w, title, surf):
    p, q, pts, weights, ku, kv = surf
    rows = []
    for row in pts:
        rows.append("(" + ",".join(f"#{w.point(c)}" for c in row) + ")")
    du, mu = knots_of(ku)
    dv, mv = knots_of(kv)
    ints = lambda xs: "(" + ",".join(str(x) for x in xs) + ")"
    reals = lambda xs: "(" + ",".join(fmt(x) for x in xs) + ")"
    cpl = "(" + ",".join(rows) + ")"
    if weights is None:
        s = w.add(
            f"B_SPLINE_SURFACE_WITH_KNOTS('{title}',{p},{q},{cpl},.UNSPECIFIED.,.F.,.F.,.F.,"
            f"{ints(mu)},{ints(mv)},{reals(du)},{reals(dv)},.UNSPECIFIED.)"
        )
    else:
        wd = "(" + ",".join(reals(r) for r in weights) + ")"
        s = w.add(
            f"(BOUNDED_SURFACE() B_SPLINE_SURFACE({p},{q},{cpl},.UNSPECIFIED.,.F.,.F.,.F.) "
            f"B_SPLINE_SURFACE_WITH_KNOTS({ints(mu)},{ints(mv)},{reals(du)},{reals(dv)},"
            f".UNSPECIFIED.) GEOMETRIC_REPRESENTATION_ITEM() RATIONAL_B_SPLINE_SURFACE({wd}) "
            f"REPRESENTATION_ITEM('{title}') SURFACE())"
        )
    return s


def write_part(w, name, title, s, tool, tech, strategy, placements):
    (setup_o, wp_o, feat_o) = placements
    wp_place = w.placement("workpiece", *wp_o)
    material = w.add("MATERIAL('EN AW-6082','aluminium',())")
    workpiece = w.add(f"WORKPIECE('blank',#{material},0.01,$,$,$,())")
    feat_place = w.placement("feature", *feat_o)
    diam, length = tool
    dim = w.add(f"MILLING_TOOL_DIMENSION({fmt(diam)},$,$,$,{fmt(diam / 2)},$,$)")
    body = w.add(f"BALL_ENDMILL(#{dim},2,.RIGHT.,.F.,$)")
    tool_i = w.add(f"CUTTING_TOOL('ball D{fmt(diam)}',#{body},(),{fmt(length)})")
    feed, rpm = tech
    tech_i = w.add(f"MILLING_TECHNOLOGY({fmt(feed / 60)},.TCP.,$,{fmt(rpm / 60)},$,.F.,.F.,.F.,$)")
    mf = w.add("MILLING_MACHINE_FUNCTIONS(.T.,$,$,.F.,$,(),.T.,$,$,())")
    if strategy[0] == "PLANE_CC":
        _, mode, normal, stepover, scallop = strategy
        tol = w.add(f"TOLERANCES(0.001,{fmt(scallop)})")
        nd = w.direction(normal)
        so = fmt(stepover) if stepover else "$"
        strat = w.add(f"PLANE_CC_STRATEGY(.{mode}.,.CLIMB.,#{tol},{so},#{nd})")
    else:
        mode, fwd, side, stepover, scallop = strategy
        tol = w.add(f"TOLERANCES(0.001,{fmt(scallop)})")
        fd = w.direction(fwd)
        sd = w.direction(side)
        so = fmt(stepover) if stepover else "$"
        strat = w.add(f"UV_STRATEGY(.{mode}.,.CLIMB.,#{tol},{so},#{fd},#{sd})")
    op = w.add(
        f"FREEFORM_OPERATION($,$,'finish {title}',20.,$,#{tool_i},#{tech_i},#{mf},$,$,$,#{strat})"
    )
    feat = w.add(f"REGION_SURFACE_LIST('free-form',#{workpiece},(#{op}),#{feat_place},$,(#{s}))")
    secplane_p = w.placement("security plane", [0, 0, 50])
    secplane = w.add(f"PLANE('security plane',#{secplane_p})")
    ws = w.add(f"MACHINING_WORKINGSTEP('finish {title}',#{secplane},#{feat},#{op},$)")
    setup_place = w.placement("setup", *setup_o)
    wps = w.add(f"WORKPIECE_SETUP(#{workpiece},#{wp_place},$,$,())")
    setup = w.add(f"SETUP('setup',#{setup_place},#{secplane},(#{wps}))")
    plan = w.add(f"WORKPLAN('main',(#{ws}),$,#{setup},$)")
    w.add(f"PROJECT('{title}',#{plan},(#{workpiece}),$,$,$)")
    text = (
        "ISO-10303-21;\nHEADER;\n"
        f"FILE_DESCRIPTION(('{title}: free-form finishing, ISO 14649-11 subset'),'2;1');\n"
        f"FILE_NAME('{name}','2026-11-23T00:00:00',('cnc'),(''),'make_surfaces.py','','');\n"
        "FILE_SCHEMA(('MACHINING_SCHEMA'));\nENDSEC;\nDATA;\n"
        + "\n".join(w.lines)
        + "\nENDSEC;\nEND-ISO-10303-21;\n"
    )
    with open(os.path.join(HERE, name), "w") as f:
        f.write(text)


def seed_surface(name="seed-surface.stp", strategy=("ZIGZAG", [1, 0], [0, 1], None, 0.02)):
    n = 10
    pts = []
    for i in range(n):
        row = []
        for j in range(n):
            x = 60.0 * i / (n - 1)
            y = 60.0 * j / (n - 1)
            z = (
                4.0 * math.sin(math.pi * x / 60.0) * math.sin(math.pi * y / 60.0)
                + 1.5 * math.cos(2.0 * math.pi * (x + 0.5 * y) / 60.0)
                + 0.02 * (x - 30.0) * (y - 30.0) / 3.0
            )
            row.append([round(x, 6), round(y, 6), round(z, 6)])
        pts.append(row)
    k = [0.0, 0.0, 0.0] + [i / 8 for i in range(1, 8)] + [1.0, 1.0, 1.0]
    write(
        name,
        "seed 000 surface",
        (2, 2, pts, None, k, k),
        (6.0, 100.0),
        (2400.0, 4485.0),
        strategy,
        ([[0, 0, 0]], [[0, 0, 0]], [[0, 0, 0]]),
    )


def torus_patch():
    big, small = 40.0, 15.0
    c = math.sqrt(0.5)
    # Poloidal arc 45..135 deg in the (radius, z) plane, weights 1, cos 45, 1.
    prof = [(big + small * c, small * c), (big, small / c), (big - small * c, small * c)]
    wprof = [1.0, c, 1.0]
    # Toroidal quarter circle 0..90 deg.
    rev = [(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    wrev = [1.0, c, 1.0]
    pts = [[[rx * cs, rx * sn, z] for (rx, z) in prof] for (cs, sn) in rev]
    weights = [[wi * wj for wj in wprof] for wi in wrev]
    k = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
    a = math.radians(30.0)
    write(
        "torus-patch.stp",
        "torus crown",
        (2, 2, pts, weights, k, k),
        (10.0, 80.0),
        (1800.0, 8000.0),
        ("ZIGZAG", [1, 0], [0, 1], 2.0, 0.01),
        (
            [[0, 0, -20.0]],
            [[20.0, 10.0, 5.0], [0, 0, 1], [math.cos(a), math.sin(a), 0]],
            [[0, 0, 0]],
        ),
    )


def cubic_wave():
    n = 8
    pts = []
    for i in range(n):
        row = []
        for j in range(n):
            x = 70.0 * i / (n - 1)
            y = 50.0 * j / (n - 1)
            z = 3.0 * math.sin(2 * math.pi * x / 70.0) * math.cos(math.pi * y / 50.0) + 0.05 * y
            row.append([round(x, 6), round(y, 6), round(z, 6)])
        pts.append(row)
    k = [0.0] * 4 + [0.2, 0.4, 0.6, 0.8] + [1.0] * 4
    write(
        "cubic-wave.stp",
        "cubic wave",
        (3, 3, pts, None, k, k),
        (8.0, 90.0),
        (3000.0, 10000.0),
        ("FORWARD", [0, 1], [-1, 0], None, 0.01),
        ([[0, 0, 0]], [[0, 0, 0]], [[5.0, 5.0, 0]]),
    )


def t_spline_bump():
    """A T-spline with local refinement: a 40 x 30 mm clamped bicubic mesh (s lines
    0, 10, 20, 30, 40; t lines 0, 7.5, 15, 22.5, 30) with two short vertical lines
    (s = 15, 25) and two short horizontal ones (t = 11.25, 18.75) around the middle:
    eight T-junctions, and a bump of 3 mm raised on the refined points only; a notch at
    one corner left out of the T-image. The local knots are written out (the reader
    checks them against its own rays)."""
    s_lines = [0.0] * 4 + [10.0, 15.0, 20.0, 25.0, 30.0] + [40.0] * 4
    t_lines = [0.0] * 4 + [7.5, 11.25, 15.0, 18.75, 22.5] + [30.0] * 4
    m, n = len(s_lines) - 1, len(t_lines) - 1
    whole_s = [2, 3, 4, 6, 8, 9, 10]
    whole_t = [2, 3, 4, 6, 8, 9, 10]
    # 0-based (line, from, to); the short lines run between lines 4 and 8 across.
    s_segs = [(i, 2, n - 2) for i in whole_s] + [(5, 4, 8), (7, 4, 8)]
    t_segs = [(j, 2, m - 2) for j in whole_t] + [(5, 4, 8), (7, 4, 8)]

    def vertical(i, j):
        return i <= 1 or i >= m - 1 or any(a == i and b <= j <= c for a, b, c in s_segs)

    def horizontal(j, i):
        return j <= 1 or j >= n - 1 or any(a == j and b <= i <= c for a, b, c in t_segs)

    def ray(lines, at, crossed):
        below = [lines[k] for k in range(at - 1, -1, -1) if crossed(k)][:2]
        above = [lines[k] for k in range(at + 1, len(lines)) if crossed(k)][:2]
        return [below[1], below[0], lines[at], above[0], above[1]]

    # A notch left out of the T-image at the corner s 30..40, t 22.5..30 (1-based lines
    # (i0, j0, i1, j1)): the UV passes cover it in two T-regions.
    hole = (9, 9, 10, 10)
    anchors, pts, sk, tk = [], [], [], []
    for i in range(2, m - 1):
        for j in range(2, n - 1):
            if not (vertical(i, j) and horizontal(j, i)):
                continue
            ks = ray(s_lines, i, lambda k: vertical(k, j))
            kt = ray(t_lines, j, lambda k: horizontal(k, i))
            # Greville abscissae: no two points of a clamped edge on one spot.
            x = sum(ks[1:4]) / 3.0
            y = sum(kt[1:4]) / 3.0
            z = 2.0 * math.sin(math.pi * x / 40.0) + 0.04 * y
            if 4 <= i <= 8 and 4 <= j <= 8:
                z += 3.0 * math.exp(-((x - 20.0) ** 2 + (y - 15.0) ** 2) / 20.0)
            anchors.append((i + 1, j + 1))
            pts.append([round(x, 6), round(y, 6), round(z, 6)])
            sk.append(ks)
            tk.append(kt)

    def surf(w):
        refs = ",".join(f"#{w.point(p)}" for p in pts)
        reals = lambda xs: "(" + ",".join(fmt(x) for x in xs) + ")"
        tuples = lambda ts: "(" + ",".join("(" + ",".join(str(x) for x in t) + ")" for t in ts) + ")"
        one = lambda ts: tuples([(a + 1, b + 1, c + 1) for a, b, c in ts])
        return w.add(
            f"T_SPLINE_SURFACE('t-spline bump',3,3,{reals(s_lines)},{reals(t_lines)},"
            f"{one(s_segs)},{one(t_segs)},({refs}),$,{tuples(anchors)},"
            f"({','.join(reals(k) for k in sk)}),({','.join(reals(k) for k in tk)}),"
            f"{tuples([hole])})"
        )

    write(
        "tspline-bump.stp",
        "t-spline bump",
        surf,
        (6.0, 90.0),
        (2400.0, 9000.0),
        ("ZIGZAG", [1, 0], [0, 1], None, 0.02),
        ([[0, 0, 0]], [[0, 0, 0]], [[10.0, 10.0, 0]]),
    )


if __name__ == "__main__":
    t_spline_bump()
    seed_surface()
    torus_patch()
    cubic_wave()
    a = math.radians(30.0)
    seed_surface(
        "seed-surface-planecc.stp",
        ("PLANE_CC", "ZIGZAG", [-math.sin(a), math.cos(a), 0.0], None, 0.02),
    )
