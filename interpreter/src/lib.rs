//! The interpreter (the industrial PC of a classic controller) and the `cnc` command.
//!
//! * [`parse`] reads a line of RS274/NGC into words; [`program`] runs the modal state
//!   machine over the lines and produces moves (lines, arcs, NURBS, dwells, the end),
//!   collecting every error with its line and column;
//! * [`blocks`] turns moves into command blocks (everything as exact NURBS, split to block
//!   capacity) and plans their feeds with look-ahead; [`window`] reads, builds, plans and
//!   checks a program window by window, each window ending where the machine is at rest
//!   whatever the plan, or at speed in a long stretch with no rest, so that a long
//!   program is never held whole;
//! * [`publish`] streams the blocks to the interpolator with back-pressure and records
//!   each one as sent in the command log ([`shared::cmdlog`]);
//! * [`estimate`] steps the planned blocks through the interpolator's engine in-process
//!   for a machining-time estimate (`cnc check --estimate`);
//! * [`step`] reads STEP-NC (ISO 10303-21 files with the ISO 14649 free-form subset)
//!   and [`surface_path`] (iso-parametric passes, `UV_STRATEGY`) or [`surface_plane`]
//!   (passes in parallel planes, `PLANE_CC_STRATEGY`) plans the ball-nose passes over
//!   their surfaces, which [`surface_blocks`] turns into surface blocks; a T-spline
//!   surface is first cut into tensor-product regions of its Bézier patches by
//!   [`tspline`];
//! * [`cam`] writes part programs of exact NURBS moves from geometry (`cnc cam`): an
//!   ellipse or its fitted offset, and the curves of a CAD STEP file ([`step::curves`]);
//! * [`process`] is the interpreter process; [`launch`] starts all three processes for
//!   `cnc run` (handing its check of the program on, [`checked`]) and folds their
//!   summaries into the run's [`report`]; [`replay`] runs a
//!   command log again (`cnc replay`) and prints one (`cnc log show`).

pub mod blocks;
mod brent;
pub mod cam;
pub mod checked;
pub mod cli;
pub mod contour;
pub mod estimate;
pub mod expr;
pub mod html;
pub mod launch;
mod mapped;
mod pages;
pub mod parse;
pub mod process;
pub mod program;
pub mod publish;
pub mod replay;
pub mod report;
pub mod rundir;
pub mod scallop;
mod spill;
pub mod step;
pub mod surface_blocks;
pub mod surface_path;
pub mod surface_plane;
pub mod tspline;
pub mod window;
