//! Surface tool-path blocks: a piece of a free-form surface, a path in its `(u, v)`
//! domain and the ball-nose tool, so the interpolator can place the tool by the surface
//! normal every cycle (seed 000 §3: `M = P_a + R·n + (H − R)·z`).
//!
//! A [`SurfaceBlock`] is self-contained: it carries its surface section (at most
//! [`MAX_SURF_CTRL`] × [`MAX_SURF_CTRL`] control points; larger surfaces are split exactly
//! by knot insertion in the interpreter, and the path is cut where it crosses from one
//! piece to the next), so a receiver keeps no state between blocks and a command log
//! replays block by block.
//!
//! The path is a NURBS in the `path` block's curve fields with `x = u`, `y = v` (`z = 0`),
//! in the surface's own parameters; `path.length_mm` is the length the cutter-contact
//! point travels on the surface, and the feeds are contact-point feeds. `path.kind` is
//! [`SURFACE_KIND`]: that code is not a [`super::BlockKind`] yet (the engine does not
//! take surface blocks), so a plain [`super::CommandBlock::validate`] refuses it as an
//! unknown kind rather than misreading it.

use super::{CommandBlock, ProtocolError, PROTOCOL_VERSION};
use crate::nurbs::surface::{SurfaceData, MAX_SURF_CTRL, MAX_SURF_DEGREE, MAX_SURF_KNOTS};
use crate::nurbs::{self, CurveError, MAX_CTRL, MAX_DEGREE};
use iceoryx2::prelude::ZeroCopySend;

/// The block kind code of a surface block (reserved next to the `BlockKind` codes).
pub const SURFACE_KIND: u32 = 4;

/// A surface piece: degrees, knots and control points `[x, y, z, w]` (mm, weight not
/// premultiplied), row-major `ctrl[i * n_v + j]`, `i` along `u`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
pub struct SurfaceSection {
    pub degree_u: u32,
    pub degree_v: u32,
    pub n_u: u32,
    pub n_v: u32,
    pub knots_u: [f64; MAX_SURF_KNOTS],
    pub knots_v: [f64; MAX_SURF_KNOTS],
    pub ctrl: [[f64; 4]; MAX_SURF_CTRL * MAX_SURF_CTRL],
}

impl SurfaceSection {
    pub const EMPTY: SurfaceSection = SurfaceSection {
        degree_u: 0,
        degree_v: 0,
        n_u: 0,
        n_v: 0,
        knots_u: [0.0; MAX_SURF_KNOTS],
        knots_v: [0.0; MAX_SURF_KNOTS],
        ctrl: [[0.0; 4]; MAX_SURF_CTRL * MAX_SURF_CTRL],
    };

    /// The section as the evaluators take it; `None` when a count exceeds the capacity
    /// (so the slices cannot be cut). Full validation is [`SurfaceBlock::validate`].
    pub fn data(&self) -> Option<SurfaceData<'_>> {
        let (p, q) = (self.degree_u as usize, self.degree_v as usize);
        let (n_u, n_v) = (self.n_u as usize, self.n_v as usize);
        if p > MAX_SURF_DEGREE || q > MAX_SURF_DEGREE || n_u > MAX_SURF_CTRL || n_v > MAX_SURF_CTRL
        {
            return None;
        }
        Some(SurfaceData {
            degree_u: p,
            degree_v: q,
            knots_u: self.knots_u.get(..n_u + p + 1)?,
            knots_v: self.knots_v.get(..n_v + q + 1)?,
            n_u,
            n_v,
            ctrl: self.ctrl.get(..n_u * n_v)?,
        })
    }

    /// Copies a surface that fits; `None` when it does not.
    pub fn from_data(s: &SurfaceData<'_>) -> Option<SurfaceSection> {
        let fits = s.degree_u <= MAX_SURF_DEGREE
            && s.degree_v <= MAX_SURF_DEGREE
            && s.n_u <= MAX_SURF_CTRL
            && s.n_v <= MAX_SURF_CTRL
            && s.knots_u.len() <= MAX_SURF_KNOTS
            && s.knots_v.len() <= MAX_SURF_KNOTS
            && s.ctrl.len() == s.n_u * s.n_v;
        if !fits {
            return None;
        }
        let mut out = SurfaceSection::EMPTY;
        out.degree_u = s.degree_u as u32;
        out.degree_v = s.degree_v as u32;
        out.n_u = s.n_u as u32;
        out.n_v = s.n_v as u32;
        out.knots_u[..s.knots_u.len()].copy_from_slice(s.knots_u);
        out.knots_v[..s.knots_v.len()].copy_from_slice(s.knots_v);
        out.ctrl[..s.ctrl.len()].copy_from_slice(s.ctrl);
        Some(out)
    }
}

/// The ball-nose tool of a surface block.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
pub struct SurfaceTool {
    /// Ball radius `R`.
    pub radius_mm: f64,
    /// Tool length `H` (gauge point above the tip).
    pub length_mm: f64,
    /// Unit tool axis `z` of the length compensation (machine +Z for 3 axes).
    pub axis: [f64; 3],
    /// `+1` or `−1`: the side of the surface the tool is on; the offset normal is
    /// `normal_sign · (S_u × S_v)/|S_u × S_v|`.
    pub normal_sign: f64,
}

/// One surface tool-path block, interpreter to interpolator.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("cnc::SurfaceBlockV1")]
pub struct SurfaceBlock {
    /// Sequence, source line, flags, feeds, limits and the `(u, v)` path NURBS
    /// (`x = u`, `y = v`, `z = 0`); `kind` is [`SURFACE_KIND`].
    pub path: CommandBlock,
    pub surface: SurfaceSection,
    pub tool: SurfaceTool,
}

impl SurfaceBlock {
    /// A surface block with an empty path, surface and tool.
    pub fn empty(seq: u64, source_line: u32) -> Self {
        let mut path = CommandBlock::empty(super::BlockKind::Motion, seq, source_line);
        path.kind = SURFACE_KIND;
        SurfaceBlock {
            path,
            surface: SurfaceSection::EMPTY,
            tool: SurfaceTool {
                radius_mm: 0.0,
                length_mm: 0.0,
                axis: [0.0, 0.0, 1.0],
                normal_sign: 1.0,
            },
        }
    }

    /// Checks everything a receiver relies on. Never panics, whatever the bytes.
    pub fn validate(&self) -> Result<(), ProtocolError> {
        let b = &self.path;
        let seq = b.seq;
        if b.protocol != PROTOCOL_VERSION {
            return Err(ProtocolError::Version { got: b.protocol });
        }
        if b.kind != SURFACE_KIND {
            return Err(ProtocolError::UnknownKind { seq, code: b.kind });
        }
        let bad = |field: &'static str| ProtocolError::BadField { seq, field };
        let not_finite = |field: &'static str, index: usize| ProtocolError::NotFinite {
            seq,
            field,
            index: index as u32,
        };
        // The path: a NURBS in (u, v).
        let (degree, n) = (b.degree as usize, b.n_ctrl as usize);
        if n > MAX_CTRL {
            let err = CurveError::TooManyControlPoints {
                n_ctrl: b.n_ctrl,
                max: MAX_CTRL as u32,
            };
            return Err(ProtocolError::Curve { seq, err });
        }
        if degree > MAX_DEGREE {
            let err = CurveError::DegreeOutOfRange { degree: b.degree };
            return Err(ProtocolError::Curve { seq, err });
        }
        if let Some(i) = b.knots().iter().position(|k| !k.is_finite()) {
            return Err(not_finite("knots", i));
        }
        if let Some(i) = b
            .ctrl()
            .iter()
            .position(|c| c.iter().any(|v| !v.is_finite()))
        {
            return Err(not_finite("ctrl", i));
        }
        nurbs::validate(degree, b.knots(), b.ctrl(), MAX_CTRL)
            .map_err(|err| ProtocolError::Curve { seq, err })?;
        if b.ctrl().iter().any(|c| c[2] != 0.0) {
            return Err(bad("path (z of a (u, v) point is not 0)"));
        }
        for (field, f) in [
            ("feed_mm_per_min", b.feed_mm_per_min),
            ("start_feed_mm_per_min", b.start_feed_mm_per_min),
            ("end_feed_mm_per_min", b.end_feed_mm_per_min),
        ] {
            if !f.is_finite() || f < 0.0 || (field == "feed_mm_per_min" && f <= 0.0) {
                return Err(bad(field));
            }
        }
        if !b.length_mm.is_finite() || b.length_mm < 0.0 {
            return Err(bad("length_mm"));
        }
        for (field, v) in [
            ("acc_mm_per_s2", b.acc_mm_per_s2),
            ("jerk_mm_per_s3", b.jerk_mm_per_s3),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(bad(field));
            }
        }
        // The surface section.
        let s = &self.surface;
        if s.degree_u == 0
            || s.degree_v == 0
            || s.degree_u as usize > MAX_SURF_DEGREE
            || s.degree_v as usize > MAX_SURF_DEGREE
        {
            return Err(bad("surface degree"));
        }
        if s.n_u as usize > MAX_SURF_CTRL || s.n_v as usize > MAX_SURF_CTRL {
            return Err(bad("surface n_u/n_v (capacity)"));
        }
        let data = s.data().ok_or(bad("surface knots (capacity)"))?;
        if let Some(i) = data
            .knots_u
            .iter()
            .chain(data.knots_v)
            .position(|k| !k.is_finite())
        {
            return Err(not_finite("surface knots", i));
        }
        if let Some(i) = data
            .ctrl
            .iter()
            .position(|c| c.iter().any(|v| !v.is_finite()))
        {
            return Err(not_finite("surface ctrl", i));
        }
        data.validate(MAX_SURF_CTRL).map_err(|_| bad("surface"))?;
        // The path stays inside the section's domain: its control points do (convex hull).
        let (u0, u1) = (data.knots_u[data.degree_u], data.knots_u[data.n_u]);
        let (v0, v1) = (data.knots_v[data.degree_v], data.knots_v[data.n_v]);
        if b.ctrl()
            .iter()
            .any(|c| c[0] < u0 || c[0] > u1 || c[1] < v0 || c[1] > v1)
        {
            return Err(bad("path (leaves the surface's (u, v) domain)"));
        }
        // The tool.
        let t = &self.tool;
        let finite = [t.radius_mm, t.length_mm, t.normal_sign]
            .iter()
            .chain(&t.axis)
            .all(|v| v.is_finite());
        if !finite || t.radius_mm <= 0.0 || t.length_mm <= t.radius_mm {
            return Err(bad("tool (radius, length)"));
        }
        let axis_len =
            (t.axis[0] * t.axis[0] + t.axis[1] * t.axis[1] + t.axis[2] * t.axis[2]).sqrt();
        if (axis_len - 1.0).abs() > 1e-9 {
            return Err(bad("tool axis (not a unit vector)"));
        }
        if t.normal_sign != 1.0 && t.normal_sign != -1.0 {
            return Err(bad("tool normal_sign"));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A valid block: a 3 x 3 biquadratic patch, the path along u at v = 0.5.
    fn good() -> SurfaceBlock {
        let mut b = SurfaceBlock::empty(7, 12);
        let k = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let ctrl: Vec<[f64; 4]> = (0..9)
            .map(|i| {
                [
                    (i / 3) as f64 * 5.0,
                    (i % 3) as f64 * 5.0,
                    0.1 * i as f64,
                    1.0,
                ]
            })
            .collect();
        let data = SurfaceData {
            degree_u: 2,
            degree_v: 2,
            knots_u: &k,
            knots_v: &k,
            n_u: 3,
            n_v: 3,
            ctrl: &ctrl,
        };
        b.surface = SurfaceSection::from_data(&data).unwrap();
        b.path.degree = 1;
        b.path.n_ctrl = 2;
        b.path.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
        b.path.ctrl[0] = [0.0, 0.5, 0.0, 1.0];
        b.path.ctrl[1] = [1.0, 0.5, 0.0, 1.0];
        b.path.feed_mm_per_min = 1000.0;
        b.path.length_mm = 10.0;
        b.path.acc_mm_per_s2 = 1000.0;
        b.path.jerk_mm_per_s3 = 1e5;
        b.tool = SurfaceTool {
            radius_mm: 3.0,
            length_mm: 100.0,
            axis: [0.0, 0.0, 1.0],
            normal_sign: 1.0,
        };
        b
    }

    #[test]
    fn a_good_block_passes_and_each_broken_field_is_named() {
        assert_eq!(good().validate(), Ok(()));
        let field = |b: SurfaceBlock| match b.validate() {
            Err(ProtocolError::BadField { field, .. }) => field.to_string(),
            Err(ProtocolError::NotFinite { field, .. }) => field.to_string(),
            Err(ProtocolError::Curve { .. }) => "curve".to_string(),
            Err(e) => e.to_string(),
            Ok(()) => "ok".to_string(),
        };
        let mut b = good();
        b.surface.n_u = 17;
        assert_eq!(field(b), "surface n_u/n_v (capacity)");
        let mut b = good();
        b.surface.knots_v[4] = 0.5;
        assert_eq!(field(b), "surface");
        let mut b = good();
        b.surface.ctrl[4][3] = 0.0;
        assert_eq!(field(b), "surface");
        let mut b = good();
        b.surface.ctrl[2][1] = f64::NAN;
        assert_eq!(field(b), "surface ctrl");
        let mut b = good();
        b.path.ctrl[1][0] = 1.5;
        assert_eq!(field(b), "path (leaves the surface's (u, v) domain)");
        let mut b = good();
        b.path.ctrl[1][2] = 1.0;
        assert_eq!(field(b), "path (z of a (u, v) point is not 0)");
        let mut b = good();
        b.tool.normal_sign = 0.0;
        assert_eq!(field(b), "tool normal_sign");
        let mut b = good();
        b.tool.length_mm = 2.0;
        assert_eq!(field(b), "tool (radius, length)");
        let mut b = good();
        b.tool.axis = [0.0, 0.0, 2.0];
        assert_eq!(field(b), "tool axis (not a unit vector)");
        let mut b = good();
        b.path.knots[1] = 0.5;
        assert_eq!(field(b), "curve");
        // A plain command block reader refuses the kind instead of misreading it.
        assert!(matches!(
            good().path.validate(),
            Err(ProtocolError::UnknownKind {
                code: SURFACE_KIND,
                ..
            })
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]
        /// Any bytes in any field: an answer, never a panic.
        #[test]
        fn arbitrary_bytes_never_panic(
            edits in proptest::collection::vec((0usize..usize::MAX, any::<u64>()), 1..8),
        ) {
            let mut b = good();
            let size = core::mem::size_of::<SurfaceBlock>();
            // SAFETY: SurfaceBlock is repr(C) of integers and floats only: every bit
            // pattern is a valid value; writes stay inside the value (offset < size - 8).
            let base = (&mut b as *mut SurfaceBlock).cast::<u8>();
            for (pos, v) in edits {
                let off = pos % (size - 8);
                unsafe { core::ptr::write_unaligned(base.add(off).cast::<u64>(), v) };
            }
            let _ = b.validate();
        }
    }
}
