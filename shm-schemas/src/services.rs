//! The iceoryx2 services whose settings every opener must agree on.
//!
//! iceoryx2 fixes a service's limits when the first process creates it;
//! another process opening it with other needs is refused
//! (`DoesNotSupportRequested...`, `IncompatibleTypes`). Whoever comes first
//! (the router, an agent, the decision maker) must therefore create a
//! service the others can open, so each such service is defined once, here.

use crate::names::RobotName;
use crate::payloads::RouterEpoch;
use iceoryx2::node::Node;
use iceoryx2::service::Service;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenOrCreateError;
use iceoryx2::service::port_factory::publish_subscribe::PortFactory;
use iceoryx2::service::service_name::ServiceName;

/// Publishers of the router epoch: the running router, and a restarted one
/// while the old one's publisher is not yet cleaned up.
pub const EPOCH_MAX_PUBLISHERS: usize = 2;
/// Subscribers of the router epoch: every agent of the robot, plus tools.
/// The same as the number of clients of the router's agent service.
pub const EPOCH_MAX_SUBSCRIBERS: usize = 512;
/// Nodes that may open the router epoch: the agents, tools, the router.
pub const EPOCH_MAX_NODES: usize = 640;

/// Errors of opening a service defined here.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The service's name is not a valid iceoryx2 service name.
    #[error("{service:?} is not a valid iceoryx2 service name")]
    Name {
        /// the service
        service: String,
    },
    /// iceoryx2 could neither open nor create the event service.
    #[error("cannot open the event service {service}: {source:?}")]
    OpenEvent {
        /// the service
        service: String,
        /// what iceoryx2 said
        #[source]
        source: iceoryx2::service::builder::event::EventOpenOrCreateError,
    },
    /// iceoryx2 could neither open nor create the service.
    #[error("cannot open {service}: {source:?}")]
    Open {
        /// the service
        service: String,
        /// what iceoryx2 said
        #[source]
        source: PublishSubscribeOpenOrCreateError,
    },
}

/// Opens (or creates) `nerve/<robot>/router/epoch`, on which a (re)started
/// router publishes its [`RouterEpoch`]: publish-subscribe, history 1 (a
/// subscriber that comes late still gets the current epoch), a buffer of 1
/// (only the newest matters), safe overflow on (a slow agent never holds
/// the router up).
pub fn router_epoch<S: Service>(
    node: &Node<S>,
    robot: &RobotName,
) -> Result<PortFactory<S, RouterEpoch, ()>, ServiceError> {
    let service = robot.router_epoch_service();
    let name: ServiceName = service.as_str().try_into().map_err(|_| ServiceError::Name { service: service.clone() })?;
    node.service_builder(&name)
        .publish_subscribe::<RouterEpoch>()
        .max_publishers(EPOCH_MAX_PUBLISHERS)
        .max_subscribers(EPOCH_MAX_SUBSCRIBERS)
        .max_nodes(EPOCH_MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(1)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|source| ServiceError::Open { service, source })
}

/// Opens (or creates) the event service paired with the router epoch (same
/// name): a router notifies it after publishing its epoch, so that the
/// agents' message checkers, which sleep until something happens, notice a
/// restarted router at once (pub-sub alone wakes nobody).
pub fn router_epoch_event<S: Service>(
    node: &Node<S>,
    robot: &RobotName,
) -> Result<iceoryx2::service::port_factory::event::PortFactory<S>, ServiceError> {
    let service = robot.router_epoch_service();
    let name: ServiceName = service.as_str().try_into().map_err(|_| ServiceError::Name { service: service.clone() })?;
    node.service_builder(&name)
        .event()
        .max_notifiers(EPOCH_MAX_PUBLISHERS)
        .max_listeners(EPOCH_MAX_SUBSCRIBERS)
        .max_nodes(EPOCH_MAX_NODES)
        .open_or_create()
        .map_err(|source| ServiceError::OpenEvent { service, source })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use iceoryx2::config::Config;
    use iceoryx2::port::update_connections::UpdateConnections;
    use iceoryx2::prelude::*;
    use std::path::Path;

    /// A world of its own (its own prefix), so the test sees no other
    /// process's services; dropping it removes its files, pass or fail.
    struct PrivateWorld {
        config: Config,
        prefix: String,
    }

    impl PrivateWorld {
        fn new(tag: &str) -> Self {
            let prefix = format!("nerve_schemas{}{tag}_", std::process::id());
            let mut config = Config::default();
            config.global.prefix = FileName::new(prefix.as_bytes()).unwrap();
            PrivateWorld { config, prefix }
        }

        fn node(&self) -> Node<ipc::Service> {
            NodeBuilder::new().config(&self.config).create::<ipc::Service>().unwrap()
        }
    }

    impl Drop for PrivateWorld {
        fn drop(&mut self) {
            fn walk(dir: &Path, prefix: &str) {
                for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
                    let p = e.path();
                    if p.is_dir() {
                        walk(&p, prefix);
                    } else if e.file_name().to_string_lossy().starts_with(prefix) {
                        let _ = std::fs::remove_file(p);
                    }
                }
            }
            walk(Path::new("/dev/shm"), &self.prefix);
            walk(Path::new("/tmp/iceoryx2"), &self.prefix);
        }
    }

    #[test]
    fn the_epoch_a_router_published_is_seen_by_a_late_subscriber() {
        let world = PrivateWorld::new("epoch");
        let node = world.node();
        let robot = RobotName::new("r1").unwrap();
        let router = router_epoch(&node, &robot).unwrap();
        let publisher = router.publisher_builder().create().unwrap();
        publisher.send_copy(RouterEpoch { epoch: 7, pid: 1, reserved: 0 }).unwrap();
        // an agent opening it afterwards, with the same settings
        let agent = router_epoch(&node, &robot).unwrap();
        let sub = agent.subscriber_builder().buffer_size(1).history_request(1).create().unwrap();
        publisher.update_connections().unwrap();
        assert_eq!(sub.receive().unwrap().map(|s| s.epoch), Some(7));
    }
}

/// The iceoryx2 service attributes every output port's service carries, so
/// that tools that know nothing of nerve (iceoryx2's `iox2 service details`)
/// and nerve's own tools (`nerve echo` without a router) can tell what a
/// port carries. Values are text.
pub mod port_attributes {
    /// The payload's stable type name (`nerve::Tick`).
    pub const TYPE: &str = "nerve.type";
    /// The layout fingerprint ([`crate::Schema::fingerprint`]) as `0x` and
    /// 16 hex digits: an input built from another definition of the type is
    /// refused.
    pub const FINGERPRINT: &str = "nerve.fingerprint";
    /// The agent that owns the port.
    pub const AGENT: &str = "nerve.agent";
    /// The port's name.
    pub const PORT: &str = "nerve.port";

    /// The text of a fingerprint, as the attribute holds it.
    pub fn fingerprint_text(fingerprint: u64) -> String {
        format!("{fingerprint:#018x}")
    }

    /// The fingerprint in an attribute's text, if it is one.
    pub fn parse_fingerprint(text: &str) -> Option<u64> {
        u64::from_str_radix(text.strip_prefix("0x")?, 16).ok()
    }

    #[cfg(test)]
    mod tests {
        #[test]
        fn a_fingerprint_reads_back() {
            let t = super::fingerprint_text(0xcbc6_bcae_8544_50d0);
            assert_eq!(t, "0xcbc6bcae854450d0");
            assert_eq!(super::parse_fingerprint(&t), Some(0xcbc6_bcae_8544_50d0));
            assert_eq!(super::fingerprint_text(1), "0x0000000000000001");
            assert_eq!(super::parse_fingerprint("cbc6"), None);
        }
    }
}
