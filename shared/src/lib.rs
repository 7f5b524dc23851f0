//! The contract all three processes share, and the math they must agree on.
//!
//! * [`protocol`]: the payloads that cross between processes (command blocks, set-points,
//!   feedback, status), their validation on receipt, and the service names of a run.
//! * [`nurbs`]: fixed-capacity rational B-spline curves: validation, evaluation of point
//!   and first two derivatives, knot insertion and exact splitting.
//! * [`path`]: the geometry of a motion block (NURBS plus the axial part of a helix).
//! * [`machine`]: the machine file (limits and the servo model).
//! * [`cmdlog`]: the command log (`commands.log`), every block exactly as sent.
//! * [`ipc`]: the services of a run and their QoS; [`trace`]: off-cycle CSV recording,
//!   its numbers written by [`decimal`];
//!   [`clock`]: monotonic integer time.
//!
//! Vocabulary: a *block* is one command (a motion along one curve, a dwell, the program
//! end); a *span* is one knot interval of a curve; a *cycle* is one interpolation period,
//! producing one *set-point*; a *miss* is a cycle that finished after its deadline.

pub mod alloc_count;
pub mod clock;
pub mod cmdlog;
pub mod decimal;
pub mod ipc;
pub mod logging;
pub mod machine;
pub mod machine_ini;
pub mod nurbs;
pub mod path;
pub mod profile;
pub mod protocol;
pub mod stop;
pub mod trace;
pub mod travel;

pub use machine::Machine;
