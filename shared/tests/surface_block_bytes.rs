//! A surface command block (`FLAG_SURFACE`) with any bytes in any field gets an answer
//! from `validate`, never a panic; a good one passes and each broken field is named.
//! (Carried over from the protocol-2 `SurfaceBlock`, which these blocks replace.)

use proptest::prelude::*;
use shared::protocol::{BlockKind, CommandBlock, ProtocolError, FLAG_SURFACE};

/// A bilinear patch (p = q = 1) and a pass across it.
fn good() -> CommandBlock {
    let mut b = CommandBlock::empty(BlockKind::Motion, 7, 12);
    b.flags = FLAG_SURFACE;
    b.degree = 1;
    b.surface.degree_v = 1;
    b.n_ctrl = 4;
    b.ctrl[0] = [0.0, 0.0, 0.0, 1.0];
    b.ctrl[1] = [0.0, 10.0, 1.0, 1.0];
    b.ctrl[2] = [10.0, 0.0, 1.0, 1.0];
    b.ctrl[3] = [10.0, 10.0, 0.0, 1.0];
    b.surface.uv_start = [0.0, 0.5];
    b.surface.uv_end = [1.0, 0.5];
    b.surface.tool_radius_mm = 3.0;
    b.surface.tool_length_mm = 100.0;
    b.surface.normal_sign = 1;
    b.feed_mm_per_min = 1200.0;
    b.length_mm = shared::path::length(&b);
    b.acc_mm_per_s2 = 1000.0;
    b.jerk_mm_per_s3 = 10_000.0;
    b
}

#[test]
fn a_good_block_passes_and_each_broken_field_is_named() {
    assert_eq!(good().validate(), Ok(BlockKind::Motion));
    let field = |b: CommandBlock| match b.validate() {
        Err(ProtocolError::BadField { field, .. }) => field.to_string(),
        Err(ProtocolError::NotFinite { field, .. }) => field.to_string(),
        Err(e) => e.to_string(),
        Ok(_) => "ok".to_string(),
    };
    let mut b = good();
    b.surface.degree_v = 9;
    assert_eq!(field(b), "degree");
    let mut b = good();
    b.n_ctrl = 5;
    assert_eq!(field(b), "n_ctrl");
    let mut b = good();
    b.ctrl[2][1] = f64::NAN;
    assert_eq!(field(b), "ctrl");
    let mut b = good();
    b.ctrl[3][3] = 0.0;
    assert_eq!(field(b), "ctrl weight");
    let mut b = good();
    b.surface.uv_end = [1.5, 0.5];
    assert_eq!(field(b), "surface uv");
    let mut b = good();
    b.surface.tool_length_mm = 2.0;
    assert_eq!(field(b), "surface tool");
    let mut b = good();
    b.surface.normal_sign = 0;
    assert_eq!(field(b), "surface normal_sign");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]
    /// Any bytes in any field: an answer, never a panic.
    #[test]
    fn arbitrary_bytes_never_panic(
        edits in proptest::collection::vec((0usize..usize::MAX, any::<u64>()), 1..8),
    ) {
        let mut b = good();
        let size = core::mem::size_of::<CommandBlock>();
        // SAFETY: CommandBlock is repr(C) of integers and floats only: every bit pattern
        // is a valid value; writes stay inside the value (offset < size - 8).
        let base = (&mut b as *mut CommandBlock).cast::<u8>();
        for (pos, v) in edits {
            let off = pos % (size - 8);
            unsafe { core::ptr::write_unaligned(base.add(off).cast::<u64>(), v) };
        }
        let _ = b.validate();
        // A block that validates can be evaluated without a panic too.
        if b.validate().is_ok() && b.is_surface() {
            let _ = shared::path::eval(&b, 0.5);
        }
    }
}
