#!/usr/bin/env python3
"""Writes cad-profile.step, the CAD example of `cnc cam curves` (run from anywhere).

A plate profile drawn in a CAD system's sketch, exported as AP214 wireframe: one
GEOMETRIC_CURVE_SET of a COMPOSITE_CURVE (the outline) and a CIRCLE (a bore), in mm and
degrees. The outline, anticlockwise from the origin:

1. a TRIMMED_CURVE of a LINE, (0,0) to (80,0), trimmed by points;
2. a TRIMMED_CURVE of a CIRCLE (centre (80,20), r 20), -90 to 0 degrees, by parameters;
3. a cubic B_SPLINE_CURVE_WITH_KNOTS on clamped uniform knots (a G5.2), from (100,20)
   to the point at u = 0.9 of curve 4's basis;
4. a TRIMMED_CURVE of a rational cubic B-spline (the complex instance, knots
   0,0,0,0,0.4,1,1,1,1), from u = 0.9 down to u = 0.1 (sense .F.);
5. a TRIMMED_CURVE of a LINE from that point to (20,60), by points (master .CARTESIAN.);
6. a TRIMMED_CURVE of an ELLIPSE (centre (20,20), semi-axes 40 along Y and 20), 0 to 90
   degrees: (20,60) to (0,20);
7. a POLYLINE (0,20), (0,8), (0,0).

The test interpreter/tests/cam_curves.rs holds the same numbers as its truth.
"""
import os

from make_surfaces import Writer, fmt

HERE = os.path.dirname(os.path.abspath(__file__))

# Curve 4's basis: rational cubic.
B4 = [(10.0, 57.0), (30.0, 82.0), (50.0, 62.0), (72.0, 86.0), (96.0, 71.0)]
W4 = [1.0, 1.5, 0.8, 1.2, 1.0]
K4 = [0.0, 0.0, 0.0, 0.0, 0.4, 1.0, 1.0, 1.0, 1.0]


def basis(i, p, k, u):
    """Cox-de Boor, the last span closed at its end."""
    if p == 0:
        if k[i] <= u < k[i + 1] or (u == k[-1] and k[i] < k[i + 1] == k[-1]):
            return 1.0
        return 0.0
    a = 0.0 if k[i + p] == k[i] else (u - k[i]) / (k[i + p] - k[i]) * basis(i, p - 1, k, u)
    b = 0.0
    if k[i + p + 1] != k[i + 1]:
        b = (k[i + p + 1] - u) / (k[i + p + 1] - k[i + 1]) * basis(i + 1, p - 1, k, u)
    return a + b


def rat(pts, w, k, u):
    n = [basis(i, 3, k, u) * w[i] for i in range(len(pts))]
    s = sum(n)
    return tuple(sum(n[i] * pts[i][d] for i in range(len(pts))) / s for d in range(2))


def main():
    w = Writer()
    mm = w.add("(LENGTH_UNIT() NAMED_UNIT(*) SI_UNIT(.MILLI.,.METRE.))")
    rad = w.add("(NAMED_UNIT(*) PLANE_ANGLE_UNIT() SI_UNIT($,.RADIAN.))")
    deg_m = w.add(f"PLANE_ANGLE_MEASURE_WITH_UNIT(PLANE_ANGLE_MEASURE(0.017453292519943295),#{rad})")
    dim = w.add("DIMENSIONAL_EXPONENTS(0.,0.,0.,0.,0.,0.,0.)")
    deg = w.add(f"(CONVERSION_BASED_UNIT('DEGREE',#{deg_m}) NAMED_UNIT(#{dim}) PLANE_ANGLE_UNIT())")
    sr = w.add("(NAMED_UNIT(*) SI_UNIT($,.STERADIAN.) SOLID_ANGLE_UNIT())")
    unc = w.add(f"UNCERTAINTY_MEASURE_WITH_UNIT(LENGTH_MEASURE(1.E-06),#{mm},'distance_accuracy_value','')")
    ctx = w.add(
        f"(GEOMETRIC_REPRESENTATION_CONTEXT(3) GLOBAL_UNCERTAINTY_ASSIGNED_CONTEXT((#{unc})) "
        f"GLOBAL_UNIT_ASSIGNED_CONTEXT((#{mm},#{deg},#{sr})) REPRESENTATION_CONTEXT('',''))"
    )

    def pt(x, y):
        return w.point([x, y, 0.0])

    def line(a, b, by_points):
        d = (b[0] - a[0], b[1] - a[1])
        length = (d[0] ** 2 + d[1] ** 2) ** 0.5
        o = pt(*a)
        v = w.add(f"VECTOR('',#{w.direction([d[0] / length, d[1] / length, 0.0])},{fmt(length)})")
        ln = w.add(f"LINE('',#{o},#{v})")
        p1, p2 = pt(*a), pt(*b)
        if by_points:
            return w.add(f"TRIMMED_CURVE('',#{ln},(#{p1}),(#{p2}),.T.,.CARTESIAN.)")
        return w.add(f"TRIMMED_CURVE('',#{ln},(#{p1},PARAMETER_VALUE(0.)),(#{p2},PARAMETER_VALUE(1.)),.T.,.PARAMETER.)")

    c1 = line((0.0, 0.0), (80.0, 0.0), False)
    circ = w.add(f"CIRCLE('',#{w.placement('', [80.0, 20.0, 0.0], [0, 0, 1], [1, 0, 0])},20.)")
    c2 = w.add(f"TRIMMED_CURVE('',#{circ},(PARAMETER_VALUE(-90.)),(PARAMETER_VALUE(0.)),.T.,.PARAMETER.)")
    a4 = rat(B4, W4, K4, 0.9)
    b4 = rat(B4, W4, K4, 0.1)
    p3 = [(100.0, 20.0), (104.0, 40.0), (96.0, 52.0), (104.0, 64.0), (a4[0] + 8.0, a4[1] + 4.0), a4]
    ids = ",".join(f"#{pt(*p)}" for p in p3)
    c3 = w.add(
        f"B_SPLINE_CURVE_WITH_KNOTS('',3,({ids}),.UNSPECIFIED.,.F.,.F.,(4,1,1,4),(0.,0.333333333333333,0.666666666666667,1.),.UNSPECIFIED.)"
    )
    ids = ",".join(f"#{pt(*p)}" for p in B4)
    r4 = w.add(
        f"(BOUNDED_CURVE() B_SPLINE_CURVE(3,({ids}),.UNSPECIFIED.,.F.,.F.) "
        f"B_SPLINE_CURVE_WITH_KNOTS((4,1,4),(0.,0.4,1.),.UNSPECIFIED.) CURVE() GEOMETRIC_REPRESENTATION_ITEM() "
        f"RATIONAL_B_SPLINE_CURVE(({','.join(fmt(x) for x in W4)})) REPRESENTATION_ITEM(''))"
    )
    c4 = w.add(f"TRIMMED_CURVE('',#{r4},(PARAMETER_VALUE(0.9)),(PARAMETER_VALUE(0.1)),.F.,.PARAMETER.)")
    c5 = line(b4, (20.0, 60.0), True)
    ell = w.add(f"ELLIPSE('',#{w.placement('', [20.0, 20.0, 0.0], [0, 0, 1], [0, 1, 0])},40.,20.)")
    c6 = w.add(f"TRIMMED_CURVE('',#{ell},(PARAMETER_VALUE(0.)),(PARAMETER_VALUE(90.)),.T.,.PARAMETER.)")
    c7 = w.add(f"POLYLINE('',({','.join(f'#{pt(*p)}' for p in [(0.0, 20.0), (0.0, 8.0), (0.0, 0.0)])}))")
    segs = ",".join(f"#{w.add(f'COMPOSITE_CURVE_SEGMENT(.CONTINUOUS.,.T.,#{c})')}" for c in [c1, c2, c3, c4, c5, c6, c7])
    outline = w.add(f"COMPOSITE_CURVE('outline',({segs}),.F.)")
    bore = w.add(f"CIRCLE('bore',#{w.placement('', [50.0, 35.0, 0.0], [0, 0, 1], [1, 0, 0])},8.)")
    cset = w.add(f"GEOMETRIC_CURVE_SET('',(#{outline},#{bore}))")
    w.add(f"GEOMETRICALLY_BOUNDED_WIREFRAME_SHAPE_REPRESENTATION('plate profile',(#{cset}),#{ctx})")
    head = [
        "ISO-10303-21;",
        "HEADER;",
        "FILE_DESCRIPTION(('plate profile: wireframe curves for cnc cam curves'),'2;1');",
        "FILE_NAME('cad-profile.step','2026-11-27T00:00:00',('cnc'),(''),'make_cad_profile.py','','');",
        "FILE_SCHEMA(('AUTOMOTIVE_DESIGN { 1 0 10303 214 1 1 1 1 }'));",
        "ENDSEC;",
        "DATA;",
    ]
    text = "\n".join(head + w.lines + ["ENDSEC;", "END-ISO-10303-21;", ""])
    with open(os.path.join(HERE, "cad-profile.step"), "w") as f:
        f.write(text)


if __name__ == "__main__":
    main()
