//! The services of one stack with the QoS every process opens them with. Keeping them in
//! one place means the three processes can never disagree on a buffer size or a type.
//!
//! Flow control: the block service has no safe overflow, so a block is never overwritten;
//! the interpreter counts a send that reached no subscriber as not sent and retries it
//! (back-pressure: a full queue waits, nothing is dropped). The cycle services (set-points,
//! feedback) keep safe overflow on so the real-time loop never blocks on a slow peer; the
//! receiver detects a gap in cycle numbers instead.

use crate::protocol::{
    CommandBlock, Feedback, Services, Setpoint, Status, BLOCK_QUEUE, CYCLE_QUEUE,
};
use iceoryx2::node::Node;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};

/// An iceoryx2 failure, as text (their error types are many and not `Clone`).
#[derive(Debug, Clone, PartialEq)]
pub struct IpcError(pub String);

impl core::fmt::Display for IpcError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "shared memory: {}", self.0)
    }
}
impl std::error::Error for IpcError {}

pub fn err(what: &str, e: impl core::fmt::Debug) -> IpcError {
    IpcError(format!("{what}: {e:?}"))
}

/// The iceoryx2 configuration of every node of the stack: iceoryx2's own (its defaults,
/// or a config file an operator put in one of the places iceoryx2 looks), except that
/// where it keeps iceoryx2's default root directory (`/tmp/iceoryx2/`) and file prefix
/// (`iox2_`), each user gets their own: `/dev/shm/iceoryx2-cnc-<uid>/` (or
/// `/tmp/iceoryx2-cnc-<uid>/` where `/dev/shm` is not a directory this user can write)
/// and `iox2u<uid>_`.
///
/// The root holds the nodes' and services' small files, and iceoryx2 syncs each one it
/// writes: about 20 `fsync` calls for the interpolator's services alone, 1–2 ms each on
/// this VM's disk and more while others build, all before the first cycle. On `/dev/shm`
/// (tmpfs, like the shared memory itself) a sync costs nothing, and nothing in the root
/// outlives a reboot in any case.
///
/// iceoryx2 creates its root directory mode 0750 for the first user who runs it, and
/// every other user's node creation then fails (`InternalError`): one root run, and no
/// one else could run the stack on that machine again. The three processes of one stack
/// are always one user's, so a root of one's own loses nothing. A root or prefix set in
/// a config file is kept as it is: that operator chose it.
pub fn config() -> &'static Config {
    static CONFIG: std::sync::OnceLock<Config> = std::sync::OnceLock::new();
    CONFIG.get_or_init(|| {
        // iceoryx2 warns, on reading its global configuration, that no config file exists
        // (we need none): only its errors are worth the operator's attention unless
        // IOX2_LOG_LEVEL asks for more. Set here, before that first read, whatever asks
        // for the configuration first (a node, or a peer looking for the services).
        set_log_level_from_env_or(LogLevel::Error);
        let mut cfg = Config::global_config().clone();
        let default = Config::default();
        // SAFETY: getuid(2) cannot fail and touches no memory of ours.
        let uid = unsafe { libc::getuid() };
        if cfg.global.root_path() == default.global.root_path() {
            let root = format!("{}/iceoryx2-cnc-{uid}/", state_parent());
            match Path::new(root.as_bytes()) {
                Ok(p) => cfg.global.set_root_path(&p),
                Err(e) => tracing::warn!("iceoryx2 root {root}: {e:?}; the default is used"),
            }
        }
        if cfg.global.prefix == default.global.prefix {
            let prefix = format!("iox2u{uid}_");
            match FileName::new(prefix.as_bytes()) {
                Ok(f) => cfg.global.prefix = f,
                Err(e) => tracing::warn!("iceoryx2 prefix {prefix}: {e:?}; the default is used"),
            }
        }
        cfg
    })
}

/// Where the per-user iceoryx2 root goes: `/dev/shm` when it is a directory this user can
/// write, else `/tmp`.
fn state_parent() -> &'static str {
    let shm = c"/dev/shm";
    // SAFETY: access(2) on a NUL-terminated path; it only reads it.
    let writable = unsafe { libc::access(shm.as_ptr(), libc::W_OK | libc::X_OK) } == 0;
    if writable && std::path::Path::new("/dev/shm").is_dir() {
        "/dev/shm"
    } else {
        "/tmp"
    }
}

/// A node of the stack; `role` names it in iceoryx2's introspection.
pub fn node<S: Service>(role: &str) -> Result<Node<S>, IpcError> {
    // (The configuration first: it sets iceoryx2's log level before anything of iceoryx2
    // reads its global configuration, see `config`.)
    let cfg = config();
    let name = NodeName::new(role).map_err(|e| err("node name", e))?;
    let node = NodeBuilder::new()
        .config(cfg)
        .name(&name)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<S>()
        .map_err(|e| err("creating node", e))?;
    // A process killed in an earlier run leaves its node, ports and shared memory behind.
    // iceoryx2 removes them on node creation by default; ask once more explicitly, so the
    // stack never depends on a configuration default for it.
    let cleaned = node.try_cleanup_dead_nodes();
    if cleaned.cleanups > 0 || cleaned.failed_cleanups > 0 {
        tracing::info!(
            "removed {} dead iceoryx2 node(s) left by earlier runs ({} could not be removed)",
            cleaned.cleanups,
            cleaned.failed_cleanups
        );
    }
    Ok(node)
}

/// Before the first service of a stack: how long a peer waits for the interpolator to
/// have created the services, before it opens (or creates) them itself all the same.
pub const CREATOR_WAIT: std::time::Duration = std::time::Duration::from_millis(200);

/// Waits until every service of `services` (name, messaging pattern) exists, fully
/// created, looking every 100 µs for at most `max`; returns whether they all do.
///
/// Why: every process opens the stack's services with `open_or_create`, and two that reach
/// one service at once collide: the one that finds it half created sleeps iceoryx2's whole
/// I/O tick (25 ms, a constant of the crate) before it looks again. Measured on the
/// butterfly under `--clock sim`: the servo-sim's services open 35 ms after its start
/// against the interpolator's 15 ms, the run's start-up a third longer. So the
/// interpolator creates them and its peers wait for that here, in short looks; a peer that
/// waited `max` in vain (no interpolator yet, a starved one) goes on as before, so this
/// changes how soon, never whether, a stack starts.
pub fn await_created<S: Service>(
    services: &[(&str, MessagingPattern)],
    max: std::time::Duration,
) -> bool {
    let names: Vec<(ServiceName, MessagingPattern)> = services
        .iter()
        .filter_map(|(n, p)| Some((name(n).ok()?, *p)))
        .collect();
    let start = std::time::Instant::now();
    loop {
        let all = names
            .iter()
            .all(|(n, p)| S::does_exist(n, config(), *p).unwrap_or(false));
        if all {
            return true;
        }
        if start.elapsed() >= max {
            return false;
        }
        std::thread::sleep(std::time::Duration::from_micros(100));
    }
}

fn name(s: &str) -> Result<ServiceName, IpcError> {
    ServiceName::new(s).map_err(|e| err("service name", e))
}

pub type PubSub<S, T> = publish_subscribe::PortFactory<S, T, ()>;

pub fn blocks<S: Service>(
    node: &Node<S>,
    svc: &Services,
) -> Result<PubSub<S, CommandBlock>, IpcError> {
    node.service_builder(&name(&svc.blocks())?)
        .publish_subscribe::<CommandBlock>()
        .max_publishers(1)
        .max_subscribers(2)
        .subscriber_max_buffer_size(BLOCK_QUEUE)
        .enable_safe_overflow(false)
        .open_or_create()
        .map_err(|e| err("block service", e))
}

pub fn setpoints<S: Service>(
    node: &Node<S>,
    svc: &Services,
) -> Result<PubSub<S, Setpoint>, IpcError> {
    node.service_builder(&name(&svc.setpoints())?)
        .publish_subscribe::<Setpoint>()
        .max_publishers(1)
        .max_subscribers(4)
        .subscriber_max_buffer_size(CYCLE_QUEUE)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err("set-point service", e))
}

pub fn feedback<S: Service>(
    node: &Node<S>,
    svc: &Services,
) -> Result<PubSub<S, Feedback>, IpcError> {
    node.service_builder(&name(&svc.feedback())?)
        .publish_subscribe::<Feedback>()
        .max_publishers(1)
        .max_subscribers(4)
        .subscriber_max_buffer_size(CYCLE_QUEUE)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err("feedback service", e))
}

pub fn status<S: Service>(node: &Node<S>, svc: &Services) -> Result<PubSub<S, Status>, IpcError> {
    node.service_builder(&name(&svc.status())?)
        .publish_subscribe::<Status>()
        .max_publishers(1)
        .max_subscribers(4)
        .history_size(1)
        .subscriber_max_buffer_size(4)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| err("status service", e))
}

/// The wake-up event that goes with a pub-sub service (same name, event pattern).
pub fn wakeup<S: Service>(
    node: &Node<S>,
    service_name: &str,
) -> Result<event::PortFactory<S>, IpcError> {
    node.service_builder(&name(service_name)?)
        .event()
        .max_notifiers(2)
        .max_listeners(2)
        .open_or_create()
        .map_err(|e| err("event service", e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Services;
    use std::time::Duration;

    fn status_of(svc: &Services) -> [(String, MessagingPattern); 1] {
        [(svc.status(), MessagingPattern::PublishSubscribe)]
    }

    fn awaited(services: &[(String, MessagingPattern)], max: Duration) -> bool {
        let refs: Vec<(&str, MessagingPattern)> =
            services.iter().map(|(n, p)| (n.as_str(), *p)).collect();
        await_created::<local::Service>(&refs, max)
    }

    /// A peer waits for the service until its creator has made it, and no longer; with no
    /// creator it gives up after `max` (and then opens or creates it itself).
    #[test]
    fn a_peer_waits_for_the_creator_and_no_longer() {
        let svc = Services::new(format!("await{}", std::process::id()));
        let wanted = status_of(&svc);
        assert!(!awaited(&wanted, Duration::from_millis(5)));
        let creator = std::thread::spawn({
            let svc = Services::new(format!("await{}", std::process::id()));
            move || {
                std::thread::sleep(Duration::from_millis(30));
                let node = node::<local::Service>("creator").unwrap();
                let made = status(&node, &svc).unwrap();
                // Held until the waiter has seen it.
                std::thread::sleep(Duration::from_millis(200));
                drop(made);
            }
        });
        assert!(awaited(&wanted, Duration::from_secs(10)));
        creator.join().unwrap();
    }

    /// The root of this user's iceoryx2 files lies on tmpfs where that is writable.
    #[test]
    fn the_root_is_on_dev_shm_where_writable() {
        let root = config().global.root_path().to_string();
        if state_parent() == "/dev/shm" {
            assert!(root.starts_with("/dev/shm/iceoryx2-cnc-"), "{root}");
        } else {
            assert!(root.starts_with("/tmp/iceoryx2-cnc-"), "{root}");
        }
    }
}
