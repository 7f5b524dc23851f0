//! The real-time side: scheduling set-up and the periodic loop over iceoryx2, the
//! received-block log fed from it, and `cnc latency-test`'s measuring loop.

pub mod cycle;
pub mod latency;
pub mod preempt;
pub mod received;
pub mod sched;
pub mod watch;
pub mod words;
