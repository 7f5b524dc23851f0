use super::*;
use shared::nurbs::reference::{cox_de_boor, piegl_tiller_surface};

/// A small deterministic generator (xorshift) so the tests need no crate.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Whole lines 3..=m−1 (1-based) in both directions and a point on every vertex.
fn tensor(
    s_lines: &[f64],
    t_lines: &[f64],
    z: impl Fn(f64, f64) -> f64,
) -> (TMesh, Vec<GivenPoint>) {
    let (m, n) = (s_lines.len() - 1, t_lines.len() - 1);
    let mesh = TMesh {
        s_lines: s_lines.to_vec(),
        t_lines: t_lines.to_vec(),
        s_segments: (2..=m - 2).map(|i| [i, 2, n - 2]).collect(),
        t_segments: (2..=n - 2).map(|j| [j, 2, m - 2]).collect(),
        holes: Vec::new(),
    };
    let mut pts = Vec::new();
    for i in 2..=m - 2 {
        for j in 2..=n - 2 {
            let (x, y) = (10.0 * i as f64, 7.0 * j as f64);
            pts.push(GivenPoint {
                anchor: [i, j],
                ctrl: [x, y, z(x, y), 1.0 + 0.1 * ((i * 3 + j) % 4) as f64],
                knots: None,
            });
        }
    }
    (mesh, pts)
}

const S_LINES: [f64; 11] = [0.0, 0.0, 0.0, 0.0, 20.0, 40.0, 60.0, 80.0, 80.0, 80.0, 80.0];
const T_LINES: [f64; 10] = [0.0, 0.0, 0.0, 0.0, 25.0, 50.0, 75.0, 75.0, 75.0, 75.0];

/// The tensor mesh with a vertical line at s = 50 inserted between s = 40 and 60, only
/// from t = 25 to 50: two T-junctions, one more span in s over one row of faces.
fn with_t_junctions() -> (TMesh, Vec<GivenPoint>) {
    let s: Vec<f64> = [&S_LINES[..6], &[50.0], &S_LINES[6..]].concat();
    let (mut mesh, mut pts) = tensor(&s, &T_LINES, |x, y| 0.02 * x * y - 0.1 * x);
    // Line 6 (0-based) holds only the piece from t-line 4 to 5.
    mesh.s_segments.retain(|seg| seg[0] != 6);
    mesh.s_segments.push([6, 4, 5]);
    pts.retain(|p| p.anchor[0] != 6 || (4..=5).contains(&p.anchor[1]));
    for p in pts.iter_mut().filter(|p| p.anchor[0] == 6) {
        p.ctrl[2] += 6.0; // a local bump a tensor mesh this coarse could not make
    }
    (mesh, pts)
}

fn close(a: [f64; 3], b: [f64; 3], tol: f64) -> bool {
    (0..3).all(|k| (a[k] - b[k]).abs() <= tol)
}

#[test]
fn the_blending_function_is_the_cox_de_boor_basis() {
    // Tolerance 1e-14: two recursions of the same definition.
    let mut rng = Rng(7);
    for k in [
        [0.0, 1.0, 2.0, 3.0, 4.0],
        [0.0, 0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 1.0, 1.0, 3.0],
        [2.0, 5.0, 5.5, 9.0, 9.0],
    ] {
        for _ in 0..200 {
            let x = k[0] - 0.5 + rng.next() * (k[4] - k[0] + 1.0);
            let (n, d) = blend(&k, x, false);
            let want = if x < k[4] {
                cox_de_boor(0, 3, &k, x)
            } else {
                0.0
            };
            let want_d = if x < k[4] {
                cox_de_boor_der(0, 3, 1, &k, x)
            } else {
                0.0
            };
            assert!((n - want).abs() < 1e-14, "{k:?} at {x}: {n} vs {want}");
            assert!((d - want_d).abs() < 1e-13, "{k:?} at {x}: {d} vs {want_d}");
        }
    }
}

#[test]
fn a_tensor_mesh_is_the_nurbs_on_its_lines() {
    // A mesh of whole lines is the tensor-product NURBS whose knot vectors are the lines:
    // the direct sum against the textbook evaluator, 1e-11 mm on a 80 x 75 mm surface.
    let (mesh, pts) = tensor(&S_LINES, &T_LINES, |x, y| (x * 0.05).sin() * 5.0 + y * 0.1);
    let ts = TSpline::new(mesh, pts).unwrap();
    assert_eq!(ts.t_junctions(), 0);
    let n_v = T_LINES.len() - 4;
    let mut ctrl = vec![[0.0; 4]; ts.points.len()];
    for p in &ts.points {
        ctrl[(p.anchor[0] - 2) * n_v + p.anchor[1] - 2] = p.ctrl;
    }
    let nurbs = OwnedSurface {
        degree_u: 3,
        degree_v: 3,
        n_u: S_LINES.len() - 4,
        n_v,
        knots_u: S_LINES.to_vec(),
        knots_v: T_LINES.to_vec(),
        ctrl,
    };
    let mut rng = Rng(11);
    for _ in 0..500 {
        let (s, t) = (rng.next() * 80.0, rng.next() * 75.0);
        let (p, ds, dt) = ts.eval(s, t);
        let r = piegl_tiller_surface(&nurbs.data(), s, t);
        assert!(close(p, r.p, 1e-11), "{s} {t}: {p:?} vs {:?}", r.p);
        assert!(close(ds, r.du, 1e-11) && close(dt, r.dv, 1e-11));
    }
}

#[test]
fn the_extracted_patches_are_the_t_spline() {
    // The reference: the patches against the direct sum over the blending
    // functions at random (s, t), point, S_s and S_t, within 1e-12 of the surface's size
    // (80 mm: 8e-11 mm), on a mesh with two T-junctions.
    let (mesh, pts) = with_t_junctions();
    let ts = TSpline::new(mesh, pts).unwrap();
    assert_eq!(ts.t_junctions(), 2);
    let regions = regions(&ts.covered(), true);
    assert_eq!(regions.len(), 1);
    let surf = ts.region_surface(&regions[0]).unwrap();
    surf.data().validate(1024).unwrap();
    let tol = 1e-12 * 80.0;
    let mut rng = Rng(3);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let (s, t) = (rng.next() * 80.0, rng.next() * 75.0);
        let (p, ds, dt) = ts.eval(s, t);
        let r = piegl_tiller_surface(&surf.data(), s, t);
        for k in 0..3 {
            worst = worst
                .max((p[k] - r.p[k]).abs())
                .max((ds[k] - r.du[k]).abs())
                .max((dt[k] - r.dv[k]).abs());
        }
    }
    assert!(worst <= tol, "worst difference {worst:e}");
    // Not a tensor-product surface of the coarse lines: the bump is there.
    let (p, _, _) = ts.eval(50.0, 37.5);
    let (q, _, _) = ts.eval(50.0, 5.0);
    assert!(
        p[2] - (0.02 * p[0] * p[1] - 0.1 * p[0]) > 1.0,
        "{p:?} {q:?}"
    );
}

#[test]
fn the_rays_give_the_knots_beside_a_t_junction() {
    let (mut mesh, _) = with_t_junctions();
    mesh.sort();
    // The point at s = 40, t = 25 sees the short line at s = 50; the one at t = 0 does not.
    let (s, t) = mesh.ray_knots([5, 4]);
    assert_eq!(s, [0.0, 20.0, 40.0, 50.0, 60.0]);
    assert_eq!(t, [0.0, 0.0, 25.0, 50.0, 75.0]);
    let (s, _) = mesh.ray_knots([5, 3]);
    assert_eq!(s, [0.0, 20.0, 40.0, 60.0, 80.0]);
    // The T-junction's own t knots run across rows that line 6 does not reach.
    let (s, t) = mesh.ray_knots([6, 4]);
    assert_eq!(s, [20.0, 40.0, 50.0, 60.0, 80.0]);
    assert_eq!(t, [0.0, 0.0, 25.0, 50.0, 75.0]);
}

fn messages(r: Result<TSpline, Vec<TError>>) -> Vec<String> {
    r.err()
        .unwrap()
        .into_iter()
        .map(|e| format!("{}: {:?}: {}", e.rule, e.point, e.message))
        .collect()
}

#[test]
fn a_user_gets_each_mistake_named() {
    // Given knots that the mesh does not give.
    let (mesh, mut pts) = with_t_junctions();
    let k = pts.iter().position(|p| p.anchor == [5, 4]).unwrap();
    pts[k].knots = Some(([0.0, 20.0, 40.0, 60.0, 80.0], [0.0, 0.0, 25.0, 50.0, 75.0]));
    let m = messages(TSpline::new(mesh, pts));
    assert_eq!(m.len(), 1, "{m:?}");
    assert!(
        m[0].contains("local knots")
            && m[0].contains("s knots (0, 20, 40, 60, 80) disagree")
            && m[0].contains("give (0, 20, 40, 50, 60)"),
        "{m:?}"
    );
    // A weight of zero, a point off the mesh, a vertex left bare.
    let (mesh, mut pts) = with_t_junctions();
    pts[0].ctrl[3] = 0.0;
    let k = pts.iter().position(|p| p.anchor == [6, 4]).unwrap();
    pts[k].anchor = [6, 3];
    let m = messages(TSpline::new(mesh, pts));
    assert!(m.iter().any(|e| e.starts_with("weights: Some(0)")), "{m:?}");
    assert!(
        m.iter()
            .any(|e| e.contains("anchor (7, 4) is no vertex of the T-mesh: no vertical segment")),
        "{m:?}"
    );
    assert!(
        m.iter()
            .any(|e| e.contains("vertex (7, 5) of the T-mesh has no control point")),
        "{m:?}"
    );
    // A segment with a loose end, lines that go back.
    let (mut mesh, pts) = with_t_junctions();
    mesh.t_segments.retain(|s| s[0] != 6);
    mesh.s_segments.push([6, 5, 6]);
    let m = messages(TSpline::new(mesh, pts.clone()));
    assert!(
        m[0].contains("ends at (7, 7), where no horizontal segment passes"),
        "{m:?}"
    );
    let (mut mesh, _) = with_t_junctions();
    mesh.s_lines[5] = 10.0;
    let m = messages(TSpline::new(mesh, pts));
    assert!(
        m[0].contains("must not decrease: line 5 is 20, line 6 is 10"),
        "{m:?}"
    );
}

fn matrix(rows: &[&str]) -> Vec<Vec<bool>> {
    rows.iter()
        .map(|r| r.chars().map(|c| c == '#').collect())
        .collect()
}

#[test]
fn t_regions_follow_the_seed_with_gaps_and_holes() {
    // Row 0 at the bottom (t grows downwards in the picture).
    let m = matrix(&[
        "######", //
        "##..##", // a hole
        "##..##", "######", ".#####", // a gap on the edge
    ]);
    let r = regions(&m, true);
    let want = [
        Region {
            s_cells: 0..6,
            t_cells: 0..1,
        },
        Region {
            s_cells: 0..2,
            t_cells: 1..3,
        },
        Region {
            s_cells: 4..6,
            t_cells: 1..3,
        },
        Region {
            s_cells: 0..6,
            t_cells: 3..4,
        },
        Region {
            s_cells: 1..6,
            t_cells: 4..5,
        },
    ];
    assert_eq!(r, want);
    // Along t: columns are the strips.
    let r = regions(&m, false);
    let want = [
        Region {
            s_cells: 0..1,
            t_cells: 0..4,
        },
        Region {
            s_cells: 1..2,
            t_cells: 0..5,
        },
        Region {
            s_cells: 2..4,
            t_cells: 0..1,
        },
        Region {
            s_cells: 2..4,
            t_cells: 3..5,
        },
        Region {
            s_cells: 4..6,
            t_cells: 0..5,
        },
    ];
    assert_eq!(r, want);
    // Every covered cell in exactly one region, no uncovered one in any.
    for along in [true, false] {
        let mut count = vec![vec![0; 6]; 5];
        for reg in regions(&m, along) {
            for t in reg.t_cells.clone() {
                for s in reg.s_cells.clone() {
                    count[t][s] += 1;
                }
            }
        }
        for t in 0..5 {
            for s in 0..6 {
                assert_eq!(count[t][s], usize::from(m[t][s]));
            }
        }
    }
}

#[test]
fn holes_leave_the_t_image_in_regions_and_bad_ones_are_named() {
    // A hole in the mesh with T-junctions: lines s 40..60 (0-based 5..7), t 25..50 (4..5).
    // Passes along s: the row below, two strips beside the hole, the row above.
    let (mut mesh, pts) = with_t_junctions();
    mesh.holes.push([5, 4, 7, 5]);
    let ts = TSpline::new(mesh, pts.clone()).unwrap();
    let (sl, tl) = ts.cell_lines();
    assert_eq!(sl, [0.0, 20.0, 40.0, 50.0, 60.0, 80.0]);
    assert_eq!(tl, [0.0, 25.0, 50.0, 75.0]);
    let r = regions(&ts.covered(), true);
    let want = [
        Region {
            s_cells: 0..5,
            t_cells: 0..1,
        },
        Region {
            s_cells: 0..2,
            t_cells: 1..2,
        },
        Region {
            s_cells: 4..5,
            t_cells: 1..2,
        },
        Region {
            s_cells: 0..5,
            t_cells: 2..3,
        },
    ];
    assert_eq!(r, want);
    // Each region's surface is the T-spline there (1e-12 of the size, 80 mm).
    let mut rng = Rng(5);
    for reg in &r {
        let surf = ts.region_surface(reg).unwrap();
        let (u0, u1) = (sl[reg.s_cells.start], sl[reg.s_cells.end]);
        let (v0, v1) = (tl[reg.t_cells.start], tl[reg.t_cells.end]);
        for _ in 0..200 {
            let (s, t) = (u0 + rng.next() * (u1 - u0), v0 + rng.next() * (v1 - v0));
            let (p, _, _) = ts.eval(s, t);
            let q = piegl_tiller_surface(&surf.data(), s, t).p;
            assert!(close(p, q, 8e-11), "{reg:?} at ({s}, {t})");
        }
    }
    // A hole past the last line, and one that leaves nothing.
    let (mut mesh, _) = with_t_junctions();
    mesh.holes.push([5, 4, 20, 5]);
    let m = messages(TSpline::new(mesh, pts.clone()));
    assert!(
        m[0].contains("t_image_holes entry 1 (6, 5, 21, 6) is no rectangle of the domain"),
        "{m:?}"
    );
    let (mut mesh, _) = with_t_junctions();
    mesh.holes.push([3, 3, 8, 6]);
    let m = messages(TSpline::new(mesh, pts));
    assert!(m[0].contains("leave nothing of the T-image"), "{m:?}");
}

#[test]
fn torn_lines_corners_and_too_many_spans_are_refused() {
    // A value on four inner lines: blending functions that jump (a tear).
    let s = [
        0.0, 0.0, 0.0, 0.0, 10.0, 20.0, 20.0, 20.0, 20.0, 30.0, 40.0, 40.0, 40.0, 40.0,
    ];
    let (mesh, pts) = tensor(&s, &T_LINES, |_, _| 0.0);
    let m = messages(TSpline::new(mesh, pts));
    assert!(
        m[0].contains("s_knot_lines repeat 20 on lines 6..=9: at most 3 times inside"),
        "{m:?}"
    );
    // Three are a crease, and allowed.
    let s = [
        0.0, 0.0, 0.0, 0.0, 10.0, 20.0, 20.0, 20.0, 30.0, 40.0, 40.0, 40.0, 40.0,
    ];
    let (mesh, pts) = tensor(&s, &T_LINES, |_, _| 0.0);
    TSpline::new(mesh, pts).unwrap();
    // A corner inside: the row t = 50 (line 5) cut short where it meets the short line
    // s = 50 (line 6), so the vertex there has only the edges left and down.
    let (mut mesh, mut pts) = with_t_junctions();
    mesh.t_segments.retain(|x| x[0] != 5);
    mesh.t_segments.push([5, 2, 6]);
    pts.retain(|p| p.anchor[1] != 5 || p.anchor[0] <= 6);
    let m = messages(TSpline::new(mesh, pts));
    assert!(
        m.iter().any(|e| e.contains("vertex (7, 6) has 2 edges")),
        "{m:?}"
    );
    // More spans than a region's surface can hold.
    let s: Vec<f64> = [
        vec![0.0; 3],
        (0..=400).map(f64::from).collect(),
        vec![400.0; 3],
    ]
    .concat();
    let mesh = TMesh {
        s_lines: s,
        t_lines: T_LINES.to_vec(),
        s_segments: Vec::new(),
        t_segments: Vec::new(),
        holes: Vec::new(),
    };
    let m = messages(TSpline::new(mesh, Vec::new()));
    assert!(
        m[0].contains("cut the domain into 400 spans; at most 341"),
        "{m:?}"
    );
}
