//! `T_SPLINE_SURFACE`: the Part 21 form read for a T-spline surface (seed 003 derives
//! `t_spline_surface` from `bounded_surface`, so it stands in a `REGION_SURFACE_LIST`;
//! the papers do not print its attributes, so this is the project's form; the mesh and the
//! rule it must keep are on [`crate::tspline`]'s page):
//!
//! ```text
//! T_SPLINE_SURFACE(name, s_degree, t_degree,
//!     s_knot_lines, t_knot_lines,     -- (reals): the value of each index line
//!     s_segments, t_segments,         -- ((line, from, to), …): the T-mesh's edges
//!     control_points,                 -- (#CARTESIAN_POINT, …)
//!     weights,                        -- (reals), or $ for all 1
//!     anchors,                        -- ((i, j), …): each point's vertex
//!     s_local_knots, t_local_knots,   -- ((5 reals), …) each, or $ to derive them
//!     t_image_holes)                  -- ((i0, j0, i1, j1), …), or $ or left out
//! ```
//!
//! Line indices count from 1, as EXPRESS lists do: `s_segments` entry `(5, 3, 7)` is the
//! piece of vertical line 5 (the fifth value of `s_knot_lines`) from horizontal line 3 to
//! 7; an anchor `(i, j)` is the crossing of vertical line `i` and horizontal line `j`.
//! The two outermost lines on each side are whole without being listed and carry no
//! points. A hole `(i0, j0, i1, j1)` leaves the rectangle between vertical lines `i0`
//! and `i1` and horizontal lines `j0` and `j1` out of the T-image: not machined, and the
//! UV passes go round it in T-regions. Degrees must be 3. The local knots, when given, must be the ones the T-mesh's
//! rays give; each problem names the control point (its place in the list and its
//! instance).

use super::entities::{err, num, untyped, Ctx, R};
use super::p21::{Instance, Param, Record};
use super::{Placement, StepError, StepSurface, TSplineRegion};
use crate::tspline::{GivenPoint, TMesh, TSpline};

/// The attribute positions (name first).
const S_LINES: usize = 3;
const T_LINES: usize = 4;
const S_SEGS: usize = 5;
const T_SEGS: usize = 6;
const POINTS: usize = 7;
const WEIGHTS: usize = 8;
const ANCHORS: usize = 9;
const S_KNOTS: usize = 10;
const T_KNOTS: usize = 11;
const HOLES: usize = 12;

impl Ctx<'_> {
    fn reals(&self, inst: &Instance, p: &Param, what: &str) -> R<Vec<f64>> {
        match untyped(p) {
            Param::List(l) => l
                .iter()
                .map(|x| {
                    num(x)
                        .ok_or_else(|| err(inst, "type", format!("{what} must be finite numbers")))
                })
                .collect(),
            _ => Err(err(inst, "type", format!("{what} must be a list `( … )`"))),
        }
    }

    /// A list of integer tuples of `len`, turned 0-based.
    fn index_tuples(
        &self,
        inst: &Instance,
        rec: &Record,
        i: usize,
        what: &str,
        len: usize,
    ) -> R<Vec<Vec<usize>>> {
        let bad = || {
            err(
                inst,
                "type",
                format!("{what} must be a list of {len} positive integers each"),
            )
        };
        self.list(inst, rec, i, what)?
            .iter()
            .map(|t| match untyped(t) {
                Param::List(l) if l.len() == len => l
                    .iter()
                    .map(|x| match untyped(x) {
                        Param::Int(n) if *n >= 1 => Ok(*n as usize - 1),
                        _ => Err(bad()),
                    })
                    .collect(),
                _ => Err(bad()),
            })
            .collect()
    }

    fn local_knots(
        &self,
        inst: &Instance,
        rec: &Record,
        i: usize,
        what: &str,
        n: usize,
    ) -> R<Option<Vec<[f64; 5]>>> {
        if matches!(rec.params.get(i).map(untyped), Some(Param::Unset)) {
            return Ok(None);
        }
        let l = self.list(inst, rec, i, what)?;
        if l.len() != n {
            return Err(err(
                inst,
                "local knots",
                format!("{what} has {} entries for {n} control points", l.len()),
            ));
        }
        l.iter()
            .enumerate()
            .map(|(k, x)| {
                let v = self.reals(inst, x, what)?;
                <[f64; 5]>::try_from(v.as_slice()).map_err(|_| {
                    err(
                        inst,
                        "local knots",
                        format!(
                            "{what} of control point {} has {} knots; a cubic blending \
                             function has 5",
                            k + 1,
                            v.len()
                        ),
                    )
                })
            })
            .collect::<R<Vec<_>>>()
            .map(Some)
    }

    /// Reads and checks a `T_SPLINE_SURFACE`, its points placed by `to_machine`.
    pub(super) fn t_spline(
        &self,
        inst: &Instance,
        to_machine: &Placement,
    ) -> Result<TSpline, Vec<StepError>> {
        self.t_spline_parts(inst, to_machine)
            .map_err(|e| vec![e])
            .and_then(|(mesh, given, ids)| {
                TSpline::new(mesh, given).map_err(|errs| {
                    errs.into_iter()
                        .map(|e| {
                            let message = match e.point {
                                Some(k) => {
                                    format!("control point {} (#{}): {}", k + 1, ids[k], e.message)
                                }
                                None => e.message,
                            };
                            err(inst, e.rule, message)
                        })
                        .collect()
                })
            })
    }

    #[allow(clippy::type_complexity)]
    fn t_spline_parts(
        &self,
        inst: &Instance,
        to_machine: &Placement,
    ) -> R<(TMesh, Vec<GivenPoint>, Vec<u64>)> {
        let rec = &inst.records[0];
        for (i, what) in [(1, "s_degree"), (2, "t_degree")] {
            let d = self.int(inst, rec, i, what)?;
            if d != crate::tspline::DEGREE as i64 {
                return Err(err(
                    inst,
                    "degree",
                    format!("{what} is {d}; T-spline surfaces are read for degree 3"),
                ));
            }
        }
        let s_lines = self.reals(
            inst,
            self.attr(inst, rec, S_LINES, "s_knot_lines")?,
            "s_knot_lines",
        )?;
        let t_lines = self.reals(
            inst,
            self.attr(inst, rec, T_LINES, "t_knot_lines")?,
            "t_knot_lines",
        )?;
        let seg = |v: Vec<Vec<usize>>| v.into_iter().map(|t| [t[0], t[1], t[2]]).collect();
        let s_segments = seg(self.index_tuples(inst, rec, S_SEGS, "s_segments", 3)?);
        let t_segments = seg(self.index_tuples(inst, rec, T_SEGS, "t_segments", 3)?);
        let refs = self.list(inst, rec, POINTS, "control_points")?;
        let mut pts = Vec::with_capacity(refs.len());
        let mut ids = Vec::with_capacity(refs.len());
        for r in refs {
            let cp = self.deref(inst, r, "control point", &["CARTESIAN_POINT"])?;
            pts.push(to_machine.apply(self.point(cp)?));
            ids.push(cp.id);
        }
        let n = pts.len();
        let weights = match rec.params.get(WEIGHTS).map(untyped) {
            Some(Param::Unset) => vec![1.0; n],
            _ => self.reals(inst, self.attr(inst, rec, WEIGHTS, "weights")?, "weights")?,
        };
        let anchors = self.index_tuples(inst, rec, ANCHORS, "anchors", 2)?;
        for (what, len) in [("weights", weights.len()), ("anchors", anchors.len())] {
            if len != n {
                return Err(err(
                    inst,
                    "control points",
                    format!("{what} has {len} entries for {n} control points"),
                ));
            }
        }
        let sk = self.local_knots(inst, rec, S_KNOTS, "s_local_knots", n)?;
        let tk = self.local_knots(inst, rec, T_KNOTS, "t_local_knots", n)?;
        if sk.is_some() != tk.is_some() {
            return Err(err(
                inst,
                "local knots",
                "give both s_local_knots and t_local_knots, or neither (`$`) to derive them",
            ));
        }
        let given = (0..n)
            .map(|k| GivenPoint {
                anchor: [anchors[k][0], anchors[k][1]],
                ctrl: [pts[k][0], pts[k][1], pts[k][2], weights[k]],
                knots: sk.as_ref().zip(tk.as_ref()).map(|(s, t)| (s[k], t[k])),
            })
            .collect();
        // Optional (a file without it has no holes).
        let holes = match rec.params.get(HOLES).map(untyped) {
            None | Some(Param::Unset) => Vec::new(),
            Some(_) => self
                .index_tuples(inst, rec, HOLES, "t_image_holes", 4)?
                .into_iter()
                .map(|t| [t[0], t[1], t[2], t[3]])
                .collect(),
        };
        let mesh = TMesh {
            s_lines,
            t_lines,
            s_segments,
            t_segments,
            holes,
        };
        Ok((mesh, given, ids))
    }
}

impl Ctx<'_> {
    /// A `T_SPLINE_SURFACE` as its T-regions (passes along `s` when `along_s`), each one
    /// tensor-product surface of the T-spline's Bézier patches.
    pub(super) fn t_spline_regions(
        &self,
        inst: &Instance,
        to_machine: &Placement,
        along_s: bool,
    ) -> Result<Vec<StepSurface>, Vec<StepError>> {
        let ts = self.t_spline(inst, to_machine)?;
        let regions = crate::tspline::regions(&ts.covered(), along_s);
        let t_junctions = ts.t_junctions();
        let count = regions.len();
        regions
            .iter()
            .enumerate()
            .map(|(k, r)| {
                let geometry = ts
                    .region_surface(r)
                    .map_err(|e| vec![err(inst, e.rule, e.message)])?;
                // Rational where the patches' weights are not all 1: the file's weights,
                // or blending functions that do not sum to 1 (a T-spline's may not).
                let rational = geometry.ctrl.iter().any(|c| c[3] != 1.0);
                let s = StepSurface {
                    id: inst.id,
                    line: inst.line,
                    geometry,
                    rational,
                    workpiece: to_machine.clone(),
                    t_spline: Some(TSplineRegion {
                        points: ts.points.len(),
                        t_junctions,
                        region: k + 1,
                        regions: count,
                        cells: (r.s_cells.len(), r.t_cells.len()),
                    }),
                };
                s.data()
                    .validate(super::entities::MAX_READ_CTRL)
                    .map_err(|e| vec![err(inst, "surface", format!("T-region {}: {e}", k + 1))])?;
                Ok(s)
            })
            .collect()
    }
}

/// The `T_SPLINE_SURFACE` instance `id` of a parsed file, checked, in the file's own
/// coordinates (no placement applied): for tests and tools that look at the surface as
/// written.
pub fn read(ex: &super::p21::Exchange, id: u64) -> Result<TSpline, Vec<StepError>> {
    let cx = Ctx {
        ex,
        errs: Vec::new(),
    };
    let inst = ex.instances.get(&id).ok_or_else(|| {
        vec![StepError {
            line: 1,
            id: Some(id),
            rule: "reference",
            message: format!("the file does not define #{id}"),
        }]
    })?;
    cx.t_spline(inst, &Placement::IDENTITY)
}
