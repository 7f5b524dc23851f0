//! Test aid: real preemption of the cycle in the middle of its compute phase.
//!
//! A [`Preemptor`] is a thread pinned to the cycle's CPU at a SCHED_FIFO priority one above
//! the cycle's. The cycle wakes it ([`Preemptor::kick`]) from inside its compute phase; the
//! kernel then switches to it at once (a higher real-time priority on the same CPU), and it
//! holds that CPU, spinning, for a set wall time before it sleeps again. The cycle has done
//! nothing different, yet its compute phase took that much longer by the wall clock: what a
//! badly set-up machine does to it, and what the deadline report must call `preempted`
//! rather than `long_compute` (`cnc run` with `CNC_INJECT_PREEMPTION=N`).
//!
//! It needs what makes preemption deterministic: a cycle at SCHED_FIFO below priority 99,
//! pinned to one CPU, and the right to set a real-time priority. Without them
//! [`Preemptor::start`] says why, and the run goes on without it.

use shared::clock::now_ns;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;

/// The competing thread and what the cycle needs to wake it.
pub struct Preemptor {
    thread: std::thread::Thread,
    /// Kicks asked for; the thread serves each at most once (a kick while it spins is
    /// folded into the spin, as a second wake-up of a running task would be).
    asked: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    handle: Option<JoinHandle<()>>,
}

impl Preemptor {
    /// Starts the thread on `cpu` at SCHED_FIFO `cycle_priority + 1`, holding the CPU for
    /// `hold_ns` per kick. Call it from the cycle's thread after its scheduling set-up.
    pub fn start(cpu: usize, cycle_priority: i32, hold_ns: u64) -> Result<Preemptor, String> {
        if cycle_priority >= 99 {
            return Err(format!(
                "the cycle runs at SCHED_FIFO {cycle_priority}, the top: nothing can preempt it"
            ));
        }
        let asked = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (ready_tx, ready_rx) = std::sync::mpsc::channel();
        let handle = {
            let (asked, stop) = (asked.clone(), stop.clone());
            std::thread::Builder::new()
                .name("preemptor".into())
                .spawn(move || {
                    let set_up = pin_and_raise(cpu, cycle_priority + 1);
                    let ok = set_up.is_ok();
                    let _ = ready_tx.send(set_up);
                    if ok {
                        serve(&asked, &stop, hold_ns);
                    }
                })
                .map_err(|e| format!("cannot start the preemptor thread: {e}"))?
        };
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Preemptor {
                thread: handle.thread().clone(),
                asked,
                stop,
                handle: Some(handle),
            }),
            Ok(Err(why)) => {
                let _ = handle.join();
                Err(why)
            }
            Err(_) => Err("the preemptor thread ended before it was set up".into()),
        }
    }

    /// Wakes the thread, which takes the CPU from the caller at once. Allocation-free and
    /// lock-free (an atomic add and a futex wake), so the cycle may call it.
    #[inline]
    pub fn kick(&self) {
        self.asked.fetch_add(1, Ordering::Release);
        self.thread.unpark();
    }
}

impl Drop for Preemptor {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        self.thread.unpark();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// Pins the calling thread to `cpu` and makes it SCHED_FIFO `priority`.
fn pin_and_raise(cpu: usize, priority: i32) -> Result<(), String> {
    // SAFETY: plain syscalls on the calling thread with valid arguments.
    unsafe {
        let size = core::mem::size_of::<libc::cpu_set_t>();
        let mut one: libc::cpu_set_t = core::mem::zeroed();
        libc::CPU_SET(cpu, &mut one);
        if libc::sched_setaffinity(0, size, &one) != 0 {
            return Err(format!(
                "pinning the preemptor to CPU {cpu} refused ({})",
                std::io::Error::last_os_error()
            ));
        }
        let param = libc::sched_param {
            sched_priority: priority,
        };
        if libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) != 0 {
            return Err(format!(
                "SCHED_FIFO {priority} for the preemptor refused ({})",
                std::io::Error::last_os_error()
            ));
        }
    }
    Ok(())
}

/// The thread's life: sleep until kicked, hold the CPU for `hold_ns`, again.
fn serve(asked: &AtomicU64, stop: &AtomicBool, hold_ns: u64) {
    let mut served = 0;
    loop {
        std::thread::park();
        if stop.load(Ordering::Acquire) {
            return;
        }
        let now_asked = asked.load(Ordering::Acquire);
        if now_asked == served {
            continue; // a spurious wake-up
        }
        served = now_asked;
        // Wall time, not CPU time: the point is how long the cycle is kept off the CPU.
        let until = now_ns() + hold_ns;
        while now_ns() < until {
            core::hint::spin_loop();
        }
    }
}
