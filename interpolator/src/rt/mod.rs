//! The real-time side: scheduling set-up and the periodic loop over iceoryx2.

pub mod cycle;
pub mod latency;
pub mod preempt;
pub mod sched;
pub mod watch;
pub mod words;
