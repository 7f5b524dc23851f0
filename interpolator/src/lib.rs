//! The interpolator: the process that owns the clock (the DSP of a classic controller).
//!
//! Each period it advances along the current command block at the planned feed
//! ([`engine`]), evaluates the exact curve, publishes one set-point to the servo-sim and
//! measures the cycle ([`timing`]): wake-up lateness, compute time, publish time, its own
//! CPU time, and every deadline miss with its cause (late wake-up, long compute, preempted
//! mid-compute, publish stall, downstream lag) and source line. [`rt::cycle::run`] is the loop over
//! iceoryx2, generic over the service type so it runs across processes (`ipc::Service`)
//! and on threads of one test (`local::Service`). [`rt::latency`] measures the machine's
//! own wake-up jitter (`cnc latency-test`), and [`latency_screen`] shows it as it runs.

pub mod cli;
pub mod deadline;
pub mod engine;
pub mod latency_screen;
pub mod rt;
pub mod summary;
pub mod timing;
