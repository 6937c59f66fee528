//! Taps: a tool's own subscription to an agent's output port, read when the
//! tool likes (zero copy, like any agent's input; the publisher is never
//! disturbed). `nerve calibrate` and `nerve demo cooperate` record a run
//! through them.

use agent_sdk::World;
use agent_sdk::ports::{SUBSCRIBER_BUFFER, existing_port_service};
use agent_sdk::world::Ipc;
use anyhow::{Result, anyhow, bail};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::Node;
use shm_schemas::{Payload, SampleHeader};
use std::time::{Duration, Instant};

/// A subscription to one output port.
pub struct Tap<T: Payload> {
    port: String,
    sub: Subscriber<Ipc, T, SampleHeader>,
}

impl<T: Payload> Tap<T> {
    /// Subscribes to `agent/port` of `world` if the port exists now.
    pub fn try_open(world: &World, node: &Node<Ipc>, agent: &str, port: &str) -> Result<Option<Self>> {
        let service = world.robot().port_service(agent, port);
        let Some(ps) = existing_port_service::<T>(node, &service) else { return Ok(None) };
        let sub = ps
            .subscriber_builder()
            .buffer_size(SUBSCRIBER_BUFFER)
            .create()
            .map_err(|e| anyhow!("cannot subscribe to {agent}/{port} of robot {}: {e:?}", world.robot()))?;
        Ok(Some(Tap { port: format!("{agent}/{port}"), sub }))
    }

    /// Subscribes to `agent/port`, waiting up to `wait` for it to appear.
    pub fn open(world: &World, node: &Node<Ipc>, agent: &str, port: &str, wait: Duration) -> Result<Self> {
        let t0 = Instant::now();
        loop {
            if let Some(t) = Self::try_open(world, node, agent, port)? {
                return Ok(t);
            }
            if t0.elapsed() > wait {
                bail!("the port {agent}/{port} of robot {} did not appear within {wait:?}", world.robot());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Calls `f` for every sample received since the last call (at most the
    /// subscriber's buffer of them: older ones are gone).
    pub fn drain(&self, mut f: impl FnMut(&SampleHeader, &T)) -> Result<()> {
        while let Some(s) = self.sub.receive().map_err(|e| anyhow!("cannot read {}: {e:?}", self.port))? {
            f(s.user_header(), s.payload());
        }
        Ok(())
    }
}
