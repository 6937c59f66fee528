//! Data payloads: fixed-size `#[repr(C)]` types sent zero-copy between agents.
//!
//! One file per domain. Every payload implements [`Payload`], which ties the
//! iceoryx2 type name (checked by iceoryx2 when a port opens a service) to the
//! name nerve uses in its registry and error messages, and makes the payload
//! printable as JSON by `nerve echo`.

pub mod head;
pub mod ir;
pub mod map;
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
pub use map::{
    MAP_CELL_HERE, MAP_CELL_VISITED, MapCell, MapCells, MapHeader, PathHeader, PathPoint, PlanRequest, PlanStatus,
    PlannedPath,
};
pub use motion::{GroundTruth, LinguisticCommand, LinguisticTerm, Odometry, SafetyStop, VelocityCommand};
pub use navigation::{ArmGraspState, GraspAction, GraspMiss, GraspPhase, GraspRequest, HELD_NOTHING};
pub use navigation::{
    CheckpointSighting, MissionCode, MissionCommand, PoseCorrection, PoseEstimate, PoseSource, VIA_PATH_MAX_LEN,
    ViaKind, ViaPath, ViaPathBuf, ViaPathHeader, ViaPoint,
};
pub use resources::{AgentLoad, LoadLevel, MAX_AGENT_LOADS, ResourceHeader, ResourceReport};
pub use router::RouterEpoch;
pub use scalar::Scalar;
pub use situation::{DangerLevel, Mode, Situation, TargetState};
pub use sonar::{SONAR_DIRECTIONS, SonarScan};
pub use tick::Tick;

pub use shm_schemas_derive::Payload;

use crate::schema::Described;
use iceoryx2::prelude::ZeroCopySend;
use serde::Serialize;
use std::fmt::Debug;

/// A type that can travel on a nerve port.
///
/// Derive it: `#[derive(Payload)]` on a `#[repr(C)]` struct with
/// `#[payload(name = "your_crate::Thing")]` gives the type name,
/// `ZeroCopySend`, the schema and this trait (see `shm-schemas-derive`).
pub trait Payload: ZeroCopySend + Described + Debug + Copy + Serialize + Send + Sync + 'static {
    /// The stable type name (`nerve::Tick`), the one iceoryx2 compares.
    fn stable_type_name() -> &'static str {
        // SAFETY: reading the name has no precondition; the unsafety of
        // `ZeroCopySend::type_name` concerns implementing it, not calling it.
        unsafe { <Self as ZeroCopySend>::type_name() }
    }

    /// A fingerprint of the layout, field by field
    /// ([`crate::Schema::fingerprint`]): two builds whose payloads share the
    /// type name but differ in any field's name, offset or type get
    /// different fingerprints, so a peer across a bridge can refuse a stale
    /// build instead of misreading it.
    fn layout_fingerprint() -> u64 {
        Self::schema().fingerprint()
    }
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
        $m!($crate::payloads::AgentLoad);
        $m!($crate::payloads::ResourceHeader);
        $m!($crate::payloads::PoseEstimate);
        $m!($crate::payloads::PoseCorrection);
        $m!($crate::payloads::CheckpointSighting);
        $m!($crate::payloads::ViaPathHeader);
        $m!($crate::payloads::ViaPoint);
        $m!($crate::payloads::MissionCommand);
        $m!($crate::payloads::GraspRequest);
        $m!($crate::payloads::ArmGraspState);
        $m!($crate::payloads::MapCell);
        $m!($crate::payloads::MapHeader);
        $m!($crate::payloads::PlanRequest);
        $m!($crate::payloads::PathPoint);
        $m!($crate::payloads::PathHeader);
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
        use crate::schema::{Described, Kind, Primitive};
        let schema = <Tick as Described>::schema();
        let tick = <Tick as Payload>::layout_fingerprint();
        assert_eq!(tick, schema.fingerprint());
        // pinned: a change of the hashing or of Tick's layout shows here
        assert_eq!(tick, 0xcbc6_bcae_8544_50d0, "stable across builds: {tick:#x}");
        let changed = |f: &dyn Fn(&mut crate::Schema)| {
            let mut s = schema.clone();
            f(&mut s);
            s.fingerprint()
        };
        assert_ne!(tick, changed(&|s| s.size = 24), "a grown struct differs");
        assert_ne!(tick, changed(&|s| s.type_name = "nerve::Tock".into()), "another name differs");
        assert_ne!(
            tick,
            changed(&|s| if let Kind::Struct { fields } = &mut s.kind {
                fields[1].name = "stamp".into()
            }),
            "a renamed field differs"
        );
        assert_ne!(
            tick,
            changed(&|s| if let Kind::Struct { fields } = &mut s.kind {
                fields.swap(0, 1)
            }),
            "swapped fields differ"
        );
        assert_ne!(
            tick,
            changed(&|s| if let Kind::Struct { fields } = &mut s.kind {
                fields[0].schema = <i64 as Described>::schema()
            }),
            "a field of another type differs"
        );
        assert!(matches!(
            &schema.kind,
            Kind::Struct { fields } if fields[0].schema.kind == Kind::Primitive { primitive: Primitive::U64 }
        ));
        assert_ne!(tick, <Scalar as Payload>::layout_fingerprint());
    }
}
