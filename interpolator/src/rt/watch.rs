//! Peer liveness, off the cycle: a background thread watches the interpreter and the
//! servo-sim, raises a flag when one has died or its port (block publisher, set-point
//! subscriber) has left the stack's services, and removes what a dead one left in shared
//! memory (so the next start finds nothing stale). The cycle only reads two atomic flags.
//!
//! The peers' processes are found from their iceoryx2 nodes (the node id holds the pid)
//! and watched through pidfds: the kernel makes a pidfd readable the moment its process
//! has exited, so the thread sleeps in `poll(2)` and wakes on a death, at no cost in
//! between. Where that is impossible (a peer on a thread of this very process, an old
//! kernel) it asks iceoryx2 for dead nodes instead, every other poll.
//!
//! Why liveness and not only silence: on this kind of VM a healthy peer's answer can be
//! late by several milliseconds (wake-up latency tails, RT throttling, steal), so a
//! silence of 5 periods alone would stop healthy runs. A dead process is different: the
//! kernel releases its iceoryx2 liveness lock the moment it dies, so "dead" is a fact, not
//! a guess, and can be acted on at once, typically within one or two periods. Silence
//! without death (a stalled peer) is still caught by the cycle's own, longer watchdog.

use crate::engine::Peer;
use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::PortFactory;
use shared::ipc::{self, IpcError};
use shared::protocol::Services;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// One watched peer: its process (a pidfd), how to ask iceoryx2 about it, the flag to
/// raise.
struct Watched<'a> {
    pidfd: Option<libc::c_int>,
    gone: &'a AtomicBool,
    /// Which poll turns ask iceoryx2 (the two peers take turns).
    turn: u64,
    cleanup: Box<dyn Fn() + 'a>,
    port_gone: Box<dyn Fn() -> bool + 'a>,
}

impl Watched<'_> {
    /// The pid of the one other process on `service` (the peer), if there is exactly one.
    fn peer_pid<S: Service, F: PortFactory<Service = S>>(service: &F) -> Option<u32> {
        let me = std::process::id();
        let mut pids = Vec::new();
        let _ = service.nodes(|state| {
            if let NodeState::Alive(view) = &state {
                if let Ok(pid) = view.id().pid::<S>() {
                    pids.push(pid.value() as u32);
                }
            }
            CallbackProgression::Continue
        });
        pids.retain(|p| *p != me);
        pids.dedup();
        match pids.as_slice() {
            [one] => Some(*one),
            _ => None,
        }
    }

    fn pidfd(pid: u32) -> Option<libc::c_int> {
        // SAFETY: pidfd_open(2) with a pid and no flags; returns a new fd or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
        (fd >= 0).then_some(fd as libc::c_int)
    }
}

#[derive(Default)]
struct Flags {
    interpreter_gone: AtomicBool,
    servo_gone: AtomicBool,
    stop: AtomicBool,
    polls: AtomicU64,
}

/// The watching thread and what it found.
pub struct PeerWatch {
    flags: Arc<Flags>,
    thread: Option<JoinHandle<()>>,
}

impl PeerWatch {
    /// Starts watching the stack `prefix`, polling every `every`. The services must exist
    /// and both peers must have their ports connected already.
    pub fn start<S: Service>(prefix: &str, every: Duration) -> Result<PeerWatch, IpcError> {
        let flags = Arc::new(Flags::default());
        let f = flags.clone();
        let prefix = prefix.to_string();
        // The services are opened on the thread itself: a node and its port factories
        // stay on the thread that made them.
        let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), IpcError>>();
        let thread = std::thread::Builder::new()
            .name("peer-watch".into())
            .spawn(move || {
                let opened = (|| {
                    let svc = Services::new(&prefix);
                    let node = ipc::node::<S>("interpolator-watch")?;
                    let blocks = ipc::blocks(&node, &svc)?;
                    let setpoints = ipc::setpoints(&node, &svc)?;
                    Ok((node, blocks, setpoints))
                })();
                let (_node, blocks, setpoints) = match opened {
                    Ok(v) => {
                        let _ = ready_tx.send(Ok(()));
                        v
                    }
                    Err(e) => {
                        let _ = ready_tx.send(Err(e));
                        return;
                    }
                };
                let servo_pid = Watched::peer_pid(&setpoints);
                let interpreter_pid = Watched::peer_pid(&blocks);
                let peers = [
                    Watched {
                        pidfd: servo_pid.and_then(Watched::pidfd),
                        gone: &f.servo_gone,
                        turn: 0,
                        cleanup: Box::new(|| {
                            let _ = setpoints.try_cleanup_dead_nodes();
                        }),
                        port_gone: Box::new(|| {
                            setpoints.dynamic_config().number_of_subscribers() == 0
                        }),
                    },
                    Watched {
                        pidfd: interpreter_pid.and_then(Watched::pidfd),
                        gone: &f.interpreter_gone,
                        turn: 1,
                        cleanup: Box::new(|| {
                            let _ = blocks.try_cleanup_dead_nodes();
                        }),
                        port_gone: Box::new(|| blocks.dynamic_config().number_of_publishers() == 0),
                    },
                ];
                let mut fds: Vec<libc::pollfd> = peers
                    .iter()
                    .filter_map(|w| w.pidfd)
                    .map(|fd| libc::pollfd {
                        fd,
                        events: libc::POLLIN,
                        revents: 0,
                    })
                    .collect();
                let timeout_ms = every.as_millis().clamp(1, 1000) as libc::c_int;
                let mut turn = 0u64;
                while !f.stop.load(Ordering::Acquire) {
                    if fds.is_empty() {
                        std::thread::sleep(every);
                    } else {
                        // SAFETY: `fds` is a valid array of `fds.len()` pollfds.
                        unsafe {
                            libc::poll(fds.as_mut_ptr(), fds.len() as libc::nfds_t, timeout_ms)
                        };
                    }
                    for w in &peers {
                        let died = w.pidfd.is_some_and(|fd| {
                            fds.iter()
                                .any(|p| p.fd == fd && p.revents & libc::POLLIN != 0)
                        });
                        if died {
                            w.gone.store(true, Ordering::Release);
                        }
                        // Without a process to watch (same process, or no pidfd), ask
                        // iceoryx2 itself, one service every other poll (~55 µs a check).
                        let ask = w.pidfd.is_none() && turn % 2 == w.turn;
                        if died || ask || turn % 64 == w.turn {
                            (w.cleanup)();
                        }
                        if (w.port_gone)() {
                            w.gone.store(true, Ordering::Release);
                        }
                    }
                    turn += 1;
                    f.polls.fetch_add(1, Ordering::Relaxed);
                }
                for fd in peers.iter().filter_map(|w| w.pidfd) {
                    // SAFETY: closing a pidfd this thread opened.
                    unsafe { libc::close(fd) };
                }
            })
            .map_err(|e| IpcError(format!("starting the peer watch: {e}")))?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(PeerWatch {
                flags,
                thread: Some(thread),
            }),
            Ok(Err(e)) => Err(e),
            Err(_) => Err(IpcError("the peer watch did not start".into())),
        }
    }

    /// The first peer found gone, if any: two atomic loads, fit for the cycle.
    #[inline]
    pub fn gone(&self) -> Option<Peer> {
        if self.flags.servo_gone.load(Ordering::Acquire) {
            Some(Peer::ServoSim)
        } else if self.flags.interpreter_gone.load(Ordering::Acquire) {
            Some(Peer::Interpreter)
        } else {
            None
        }
    }

    /// Whether the servo-sim was found gone.
    #[inline]
    pub fn servo_gone(&self) -> bool {
        self.flags.servo_gone.load(Ordering::Acquire)
    }

    /// Liveness checks made so far.
    pub fn polls(&self) -> u64 {
        self.flags.polls.load(Ordering::Relaxed)
    }
}

impl Drop for PeerWatch {
    fn drop(&mut self) {
        self.flags.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
