//! The servo-sim: the drives and the machine. Per axis a position loop and a velocity loop
//! over a simple mechanical model ([`axis`]), stepped in lock-step with the set-points
//! ([`run`]), answering each set-point with feedback: measured position and following
//! error (commanded minus measured).

pub mod axis;
pub mod cli;
pub mod run;
