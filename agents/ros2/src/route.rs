//! Which thread puts a published topic's messages on the wire, and the
//! publishers the task thread puts with.
//!
//! A topic of small messages (Twist, Odometry, TF, LaserScan, Range, and a
//! field-by-field mapping of a layout up to [`TASK_LAYOUT_MAX`] bytes) is
//! put by the task thread itself, in the step that converted it, with
//! Zenoh's synchronous put: no hand-off to another thread, no wake-up of
//! it (issue 44: the hand-off was most of what the agent added to a raw
//! put). A topic that may carry large messages (camera Images, about
//! 900 KB at 640x480 rgb8) is handed to the link thread, as before.
//!
//! Why such a put cannot hold the real-time task for long:
//!
//! * every publisher is declared with `CongestionControl::Drop`, for
//!   reliable topics too (as before): a put never waits for the network;
//!   when the link's queue has no free batch it waits at most Zenoh's
//!   `wait_before_drop` (1 ms by default) and drops, and while the queue
//!   stays congested the next puts drop at once;
//! * a small message fits one batch (64 KB), so it is never fragmented
//!   (a fragmented message may wait `max_wait_before_drop_fragments`,
//!   50 ms);
//! * Zenoh serialises the puts of one priority under one lock, held
//!   through a large message's fragmentation. The link thread's topics
//!   are therefore published at priority `DataLow`, the task's at the
//!   default `Data` (rmw_zenoh's): an Image being cut into fragments never
//!   holds the lock a Twist waits for (with QoS on the transport, Zenoh's
//!   and rmw_zenohd's default);
//! * one topic is put by one thread only, so its attachment's sequence
//!   numbers stay in the order of its messages.

use crate::config::{PubMap, Publish};
use crate::link::Publisher;
use std::sync::{Mutex, MutexGuard};
use zenoh::qos::Priority;

/// The largest nerve layout (bytes) whose field-by-field mapping the task
/// thread puts itself. Its CDR is at most about 8 bytes per layout byte
/// (a `u8` into a `float64`) plus the ROS type's fixed fields, far below a
/// Zenoh batch (64 KB), so it is never fragmented.
pub const TASK_LAYOUT_MAX: usize = 4096;

/// The thread that puts a topic's messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Route {
    /// the task thread, in the step that converted them (small messages)
    Task,
    /// the link thread, handed over through a bounded channel (messages
    /// that may be large: Images)
    Link,
}

impl Route {
    /// The route of a `[[publish]]`: by its conversion, and for a
    /// field-by-field mapping by the size of its nerve layout.
    pub fn of(p: &Publish) -> Route {
        match p.map {
            PubMap::FramesToImage => Route::Link,
            PubMap::User => match &p.user {
                Some(m) if m.schema.size <= TASK_LAYOUT_MAX => Route::Task,
                _ => Route::Link,
            },
            PubMap::OdometryToOdometry
            | PubMap::OdometryToTf
            | PubMap::TruthToOdometry
            | PubMap::VelocityToTwist
            | PubMap::SonarToLaserScan
            | PubMap::SonarToRange => Route::Task,
        }
    }

    /// The Zenoh priority of the topic's publisher: the link thread's
    /// large messages below the task's, so that their fragmentation never
    /// holds the queue the task puts into.
    pub fn priority(self) -> Priority {
        match self {
            Route::Task => Priority::DEFAULT,
            Route::Link => Priority::DataLow,
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// What became of a message the task put.
#[derive(Debug)]
pub enum Put {
    /// on the wire (or in Zenoh's queue for it)
    Sent,
    /// no session yet (the router has not answered): nobody could receive it
    NotOpen,
    /// Zenoh refused the put
    Failed(zenoh::Error),
}

/// The publishers of the task's topics ([`Route::Task`]), by topic number.
/// The link thread fills them when its session opens and takes them back
/// before it closes the session; the task only puts with them. The lock is
/// the task's alone but for those two moments.
#[derive(Debug, Default)]
pub struct TaskPublishers {
    slots: Mutex<Vec<Option<Publisher>>>,
}

impl TaskPublishers {
    /// Puts `bytes` as topic `topic`'s next message, with its attachment.
    pub fn put(&self, topic: usize, bytes: Vec<u8>) -> Put {
        let mut slots = lock(&self.slots);
        match slots.get_mut(topic).and_then(Option::as_mut) {
            Some(p) => match p.put(bytes) {
                Ok(()) => Put::Sent,
                Err(e) => Put::Failed(e),
            },
            None => Put::NotOpen,
        }
    }

    /// The link thread's session is open: these are the task's publishers
    /// (`None` for the link thread's topics).
    pub fn fill(&self, publishers: Vec<Option<Publisher>>) {
        *lock(&self.slots) = publishers;
    }

    /// Takes the publishers back (the session is about to close).
    pub fn take(&self) -> Vec<Option<Publisher>> {
        std::mem::take(&mut *lock(&self.slots))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn publish(map: PubMap) -> Publish {
        Publish {
            input: "in".into(),
            topic: "/t".into(),
            ros_type: "geometry_msgs/msg/Twist".into(),
            map,
            frame_id: "odom".into(),
            child_frame_id: "base_link".into(),
            qos: crate::wire::Qos::default(),
            user: None,
        }
    }

    /// Images go to the link thread at a lower priority; every built-in
    /// small message is put by the task at rmw_zenoh's default priority.
    #[test]
    fn images_go_to_the_link_thread_small_messages_stay_on_the_task() {
        assert_eq!(Route::of(&publish(PubMap::FramesToImage)), Route::Link);
        for m in [
            PubMap::OdometryToOdometry,
            PubMap::OdometryToTf,
            PubMap::TruthToOdometry,
            PubMap::VelocityToTwist,
            PubMap::SonarToLaserScan,
            PubMap::SonarToRange,
        ] {
            assert_eq!(Route::of(&publish(m)), Route::Task, "{m:?}");
        }
        // a user mapping without its plan cannot be put by anyone: not the task
        assert_eq!(Route::of(&publish(PubMap::User)), Route::Link);
        assert_eq!(Route::Task.priority(), Priority::Data);
        assert_eq!(Route::Link.priority(), Priority::DataLow);
        assert!(Priority::DataLow as u8 > Priority::Data as u8, "a larger number is a lower priority");
    }

    /// A field-by-field mapping goes by the size of its nerve layout.
    #[test]
    fn a_user_mapping_goes_by_its_layout_size() {
        let plan = |fields: &str| {
            let text = format!(
                "node = \"n\"\n[[type]]\nname = \"lab::T\"\nfields = {fields}\n\
                 [[publish]]\ninput = \"t\"\nfrom = \"lab::T\"\ntopic = \"/t\"\ntype = \"sensor_msgs/msg/LaserScan\"\n"
            );
            let cfg =
                crate::config::parse(std::path::Path::new("t.toml"), &text, "ros2").expect("a valid configuration");
            cfg.publish.into_iter().next().expect("one publish")
        };
        // a nerve array of f32 fills LaserScan's `ranges` sequence
        let small = plan("[[\"ranges\", \"[f32; 4]\"]]");
        assert_eq!(Route::of(&small), Route::Task);
        let at = plan(&format!("[[\"ranges\", \"[f32; {}]\"]]", TASK_LAYOUT_MAX / 4));
        assert_eq!(Route::of(&at), Route::Task);
        let large = plan(&format!("[[\"ranges\", \"[f32; {}]\"]]", TASK_LAYOUT_MAX / 4 + 1));
        assert_eq!(Route::of(&large), Route::Link);
    }
}
