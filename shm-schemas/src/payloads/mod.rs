//! Data payloads: fixed-size `#[repr(C)]` types sent zero-copy between agents.
//!
//! One file per domain. Every payload implements [`Payload`], which ties the
//! iceoryx2 type name (checked by iceoryx2 when a port opens a service) to the
//! name nerve uses in its registry and error messages, and makes the payload
//! printable as JSON by `nerve echo`.

pub mod head;
pub mod ir;
pub mod motion;
pub mod navigation;
pub mod resources;
pub mod router;
pub mod scalar;
pub mod situation;
pub mod sonar;
pub mod tick;

pub use head::{HeadCommand, HeadState};
pub use ir::IrSighting;
pub use motion::{GroundTruth, LinguisticCommand, LinguisticTerm, Odometry, SafetyStop, VelocityCommand};
pub use navigation::{ArmGraspState, GraspAction, GraspMiss, GraspPhase, GraspRequest, HELD_NOTHING};
pub use navigation::{
    CheckpointSighting, MAX_VIA_POINTS, MissionCode, MissionCommand, PoseCorrection, PoseEstimate, PoseSource, ViaKind,
    ViaPath,
};
pub use resources::{AgentLoad, LoadLevel, MAX_AGENT_LOADS, ResourceReport};
pub use router::RouterEpoch;
pub use scalar::Scalar;
pub use situation::{DangerLevel, Mode, Situation, TargetState};
pub use sonar::{SONAR_DIRECTIONS, SonarScan};
pub use tick::Tick;

use iceoryx2::prelude::ZeroCopySend;
use serde::Serialize;
use std::fmt::Debug;

/// A type that can travel on a nerve port.
///
/// Derive it with `#[derive(ZeroCopySend)]`, `#[repr(C)]` and
/// `#[type_name("nerve::Thing")]`, then `impl Payload for Thing {}`.
pub trait Payload: ZeroCopySend + Debug + Copy + Serialize + Send + Sync + 'static {
    /// The stable type name (`nerve::Tick`), the one iceoryx2 compares.
    fn stable_type_name() -> &'static str {
        // SAFETY: reading the name has no precondition; the unsafety of
        // `ZeroCopySend::type_name` concerns implementing it, not calling it.
        unsafe { <Self as ZeroCopySend>::type_name() }
    }

    /// A fingerprint of the layout: two builds whose payloads share the type
    /// name but differ in size or alignment get different fingerprints, so a
    /// peer across a bridge can refuse a stale build instead of misreading it.
    /// (Today the layout is summarised by name, size and alignment; a
    /// field-by-field schema can refine it without changing callers.)
    fn layout_fingerprint() -> u64 {
        layout_fingerprint(Self::stable_type_name(), std::mem::size_of::<Self>(), std::mem::align_of::<Self>())
    }
}

/// The fingerprint of a layout given by type name, size and alignment
/// (64-bit FNV-1a over the three): what [`Payload::layout_fingerprint`] is
/// made of, and what a tool that knows a type only by these figures compares.
pub fn layout_fingerprint(type_name: &str, size: usize, align: usize) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET;
    let size = size as u64;
    let align = align as u64;
    for b in type_name.bytes().chain([0u8]).chain(size.to_le_bytes()).chain(align.to_le_bytes()) {
        h ^= u64::from(b);
        h = h.wrapping_mul(PRIME);
    }
    h
}

/// Calls `$m!(Type)` for every payload type this build knows, so that tools
/// (`nerve echo`, `nerve hz`) can open a port whose type they learn at run time.
#[macro_export]
macro_rules! for_each_payload {
    ($m:ident) => {
        $m!($crate::payloads::Tick);
        $m!($crate::payloads::RouterEpoch);
        $m!($crate::payloads::Scalar);
        $m!($crate::ring::RingNotice);
        $m!($crate::payloads::SonarScan);
        $m!($crate::payloads::VelocityCommand);
        $m!($crate::payloads::LinguisticCommand);
        $m!($crate::payloads::SafetyStop);
        $m!($crate::payloads::Odometry);
        $m!($crate::payloads::GroundTruth);
        $m!($crate::payloads::IrSighting);
        $m!($crate::payloads::HeadCommand);
        $m!($crate::payloads::HeadState);
        $m!($crate::payloads::Situation);
        $m!($crate::payloads::Mode);
        $m!($crate::payloads::ResourceReport);
        $m!($crate::payloads::PoseEstimate);
        $m!($crate::payloads::PoseCorrection);
        $m!($crate::payloads::CheckpointSighting);
        $m!($crate::payloads::ViaPath);
        $m!($crate::payloads::MissionCommand);
        $m!($crate::payloads::GraspRequest);
        $m!($crate::payloads::ArmGraspState);
    };
}

/// The type names of every payload this build knows.
pub fn known_type_names() -> Vec<&'static str> {
    let mut v = Vec::new();
    macro_rules! push {
        ($t:ty) => {
            v.push(<$t as Payload>::stable_type_name());
        };
    }
    for_each_payload!(push);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints_tell_layouts_apart() {
        let tick = <Tick as Payload>::layout_fingerprint();
        assert_eq!(tick, layout_fingerprint("nerve::Tick", 16, 8), "stable across builds");
        assert_ne!(tick, layout_fingerprint("nerve::Tick", 24, 8), "a grown struct differs");
        assert_ne!(tick, layout_fingerprint("nerve::Tock", 16, 8), "another name differs");
        assert_ne!(tick, <Scalar as Payload>::layout_fingerprint());
    }
}
