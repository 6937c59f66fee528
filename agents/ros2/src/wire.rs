//! rmw_zenoh's wire conventions (its `docs/design.md`, sections "Topic and
//! Service name mapping to Zenoh key expressions", "Graph Cache" and
//! "Publishers"): the data key of a topic, the liveliness tokens of a node
//! and its publishers and subscriptions, the compact QoS text in a token,
//! and the attachment every message carries.
//!
//! | what | form |
//! |---|---|
//! | data key | `<domain>/<topic without leading />/<dds type>/<type hash>` |
//! | node token | `@ros2_lv/<domain>/<session id>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>` |
//! | entity token | `@ros2_lv/<domain>/<session id>/<node id>/<entity id>/MP\|MS/<enclave>/<namespace>/<node>/<topic>/<dds type>/<type hash>/<qos>` |
//! | attachment | sequence number i64 LE, source timestamp i64 LE (ns since the epoch), GID length u8 (16), GID 16 bytes |
//!
//! In tokens, names are mangled: each `/` becomes `%`, and an empty
//! namespace or enclave is `%`.

use crate::type_hash;

/// The ROS 2 distribution the other side runs: it decides the type hash in
/// keys and tokens.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Distro {
    /// Humble: no type hashes, the literal `TypeHashNotSupported`.
    Humble,
    /// Jazzy and later: RIHS01 hashes.
    #[default]
    Jazzy,
    /// Kilted (as Jazzy).
    Kilted,
    /// Rolling (as Jazzy).
    Rolling,
}

/// What Humble's rmw_zenoh puts where a type hash goes.
pub const HASH_NOT_SUPPORTED: &str = "TypeHashNotSupported";

impl Distro {
    /// The type hash of `ros_type` (`pkg/msg/Name`) as this distribution
    /// writes it in keys, or `None` for a type that is not vendored.
    pub fn type_hash(self, ros_type: &str) -> Option<&'static str> {
        let h = type_hash(ros_type)?;
        Some(if self == Distro::Humble { HASH_NOT_SUPPORTED } else { h })
    }
}

/// `geometry_msgs/msg/Twist` → `geometry_msgs::msg::dds_::Twist_`, the type
/// name DDS (and so rmw_zenoh) uses. `None` when the name is not
/// `pkg/msg/Name`.
pub fn dds_type_name(ros_type: &str) -> Option<String> {
    match ros_type.split('/').collect::<Vec<_>>().as_slice() {
        [pkg, kind, name] if !pkg.is_empty() && !name.is_empty() && (*kind == "msg" || *kind == "srv") => {
            Some(format!("{pkg}::{kind}::dds_::{name}_"))
        }
        _ => None,
    }
}

/// Each `/` replaced by `%`; an empty name is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() { "%".into() } else { name.replace('/', "%") }
}

/// The fully qualified name of `topic` in `namespace`: an absolute topic
/// (`/odom`) stays; a relative one (`odom`) goes under the namespace
/// (`/robot1/odom`, or `/odom` in the root namespace). No trailing `/`.
pub fn qualified_topic(namespace: &str, topic: &str) -> String {
    let topic = topic.trim_end_matches('/');
    if topic.starts_with('/') { topic.to_owned() } else { format!("{}/{topic}", namespace.trim_end_matches('/')) }
}

/// The data key of a topic: `<domain>/<qualified topic without its leading
/// />/<dds type>/<type hash>`.
pub fn topic_key(domain: u32, qualified_topic: &str, dds_type: &str, type_hash: &str) -> String {
    format!("{domain}/{}/{dds_type}/{type_hash}", qualified_topic.trim_start_matches('/'))
}

/// The key under which a transient-local publisher answers late joiners,
/// and its publisher-detection liveliness token, as zenoh-ext's
/// `AdvancedPublisher` (which rmw_zenoh uses for TRANSIENT_LOCAL) declares
/// them: `<data key>/@adv/pub/<session id>/<entity id>/_` (`_`: no
/// metadata). An `AdvancedSubscriber` with history queries
/// `<data key>/@adv/**` when it starts and, with late-publisher detection,
/// each publisher whose token appears.
pub fn cache_key(data_key: &str, session: &str, entity: u32) -> String {
    format!("{data_key}/@adv/pub/{session}/{entity}/_")
}

/// The QoS of a publisher or subscription, as far as the agent sets it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// RELIABLE (true) or BEST_EFFORT
    pub reliable: bool,
    /// TRANSIENT_LOCAL (true) or VOLATILE
    pub transient_local: bool,
    /// KEEP_LAST depth
    pub depth: u32,
}

impl Default for Qos {
    fn default() -> Self {
        Qos { reliable: true, transient_local: false, depth: 10 }
    }
}

impl Qos {
    /// The compact text of a token:
    /// `<reliability>:<durability>:<history>,<depth>:<deadline s>,<ns>:<lifespan s>,<ns>:<liveliness>,<s>,<ns>`,
    /// each item empty when it is rmw_zenoh's default (reliable, volatile,
    /// keep-last, no deadline, no lifespan, automatic liveliness); otherwise
    /// the value of the `rmw_qos_*_policy_e` enum (best effort 2, transient
    /// local 1). The depth is always written.
    pub fn keyexpr(&self) -> String {
        let reliability = if self.reliable { "" } else { "2" };
        let durability = if self.transient_local { "1" } else { "" };
        format!("{reliability}:{durability}:,{}:,:,:,,", self.depth)
    }
}

/// The kind of a graph entity, as tokens name it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// `MP`, a message publisher
    Publisher,
    /// `MS`, a message subscription
    Subscription,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// Who a token speaks for: the node, in its session and domain.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeId {
    /// `ROS_DOMAIN_ID`
    pub domain: u32,
    /// the Zenoh session's id, as Zenoh prints it
    pub session: String,
    /// the node's number in the session
    pub node: u32,
    /// the SROS enclave (empty: none)
    pub enclave: String,
    /// the namespace (empty or `/`: the root)
    pub namespace: String,
    /// the node's name
    pub name: String,
}

impl NodeId {
    fn prefix(&self, entity: u32, kind: &str) -> String {
        let ns = if self.namespace == "/" { "" } else { &self.namespace };
        format!(
            "@ros2_lv/{}/{}/{}/{entity}/{kind}/{}/{}/{}",
            self.domain,
            self.session,
            self.node,
            mangle(&self.enclave),
            mangle(ns),
            self.name
        )
    }

    /// The node's own token (`NN`, its entity id is its node id).
    pub fn node_token(&self) -> String {
        self.prefix(self.node, "NN")
    }

    /// The token of the node's publisher or subscription number `entity`.
    pub fn entity_token(
        &self,
        kind: EntityKind,
        entity: u32,
        qualified_topic: &str,
        dds_type: &str,
        type_hash: &str,
        qos: &Qos,
    ) -> String {
        format!(
            "{}/{}/{dds_type}/{type_hash}/{}",
            self.prefix(entity, kind.code()),
            mangle(qualified_topic),
            qos.keyexpr()
        )
    }
}

/// The attachment of a message: who sent it, when, and its number.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// the publisher's sequence number (from 1)
    pub sequence_number: i64,
    /// when it was published, ns since the UNIX epoch
    pub source_timestamp: i64,
    /// the publisher's GID
    pub gid: [u8; 16],
}

/// The length of an encoded [`Attachment`].
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + 16;

/// Why an attachment was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AttachmentError {
    /// Not 33 bytes.
    #[error("attachment of {len} byte(s), expected {ATTACHMENT_LEN} (sequence i64, timestamp i64, GID length, GID)")]
    Length {
        /// its length
        len: usize,
    },
    /// The GID length byte is not 16.
    #[error("attachment names a GID of {len} byte(s), expected 16")]
    GidLength {
        /// the length byte
        len: u8,
    },
}

impl Attachment {
    /// The 33 bytes of the attachment.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut b = [0u8; ATTACHMENT_LEN];
        b[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        b[8..16].copy_from_slice(&self.source_timestamp.to_le_bytes());
        b[16] = 16;
        b[17..].copy_from_slice(&self.gid);
        b
    }

    /// Reads an attachment.
    pub fn decode(b: &[u8]) -> Result<Self, AttachmentError> {
        if b.len() != ATTACHMENT_LEN {
            return Err(AttachmentError::Length { len: b.len() });
        }
        if b[16] != 16 {
            return Err(AttachmentError::GidLength { len: b[16] });
        }
        let mut seq = [0u8; 8];
        seq.copy_from_slice(&b[..8]);
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&b[8..16]);
        let mut gid = [0u8; 16];
        gid.copy_from_slice(&b[17..]);
        Ok(Attachment { sequence_number: i64::from_le_bytes(seq), source_timestamp: i64::from_le_bytes(ts), gid })
    }
}

/// A GID for an entity: the first 16 bytes of SHA-256 of its token, unique
/// as long as the tokens are (they carry the session id).
pub fn gid_of(token: &str) -> [u8; 16] {
    let h = crate::idl::sha256(token.as_bytes());
    let mut g = [0u8; 16];
    g.copy_from_slice(&h[..16]);
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    // The expected strings below are the examples of rmw_zenoh's
    // docs/design.md (rolling, 2025), rebuilt from their parts.
    const STRING_HASH: &str = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";

    #[test]
    fn data_keys_as_the_design_document_gives_them() {
        let dds = dds_type_name("std_msgs/msg/String").expect("name");
        assert_eq!(dds, "std_msgs::msg::dds_::String_");
        assert_eq!(
            topic_key(0, &qualified_topic("", "chatter"), &dds, STRING_HASH),
            format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        assert_eq!(
            topic_key(0, &qualified_topic("/robot1", "chatter"), &dds, STRING_HASH),
            format!("0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        assert_eq!(qualified_topic("/robot1", "/cmd_vel"), "/cmd_vel");
        assert_eq!(dds_type_name("geometry_msgs/msg/Twist").as_deref(), Some("geometry_msgs::msg::dds_::Twist_"));
        assert_eq!(dds_type_name("Twist"), None);
        // the distro decides the hash
        assert_eq!(
            Distro::Jazzy.type_hash("geometry_msgs/msg/Twist"),
            Some("RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
        );
        assert_eq!(Distro::Humble.type_hash("geometry_msgs/msg/Twist"), Some("TypeHashNotSupported"));
        assert_eq!(Distro::Jazzy.type_hash("my_msgs/msg/Unknown"), None);
    }

    #[test]
    fn liveliness_tokens_as_the_design_document_gives_them() {
        let listener = NodeId {
            domain: 2,
            session: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            node: 0,
            enclave: String::new(),
            namespace: String::new(),
            name: "listener".into(),
        };
        assert_eq!(listener.node_token(), "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener");
        assert_eq!(
            listener.entity_token(
                EntityKind::Subscription,
                10,
                "/chatter",
                "std_msgs::msg::dds_::String_",
                STRING_HASH,
                &Qos { reliable: true, transient_local: false, depth: 10 }
            ),
            format!(
                "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
            )
        );
        let talker = NodeId { session: "8b20917502ee955ac4476e0266340d5c".into(), name: "talker".into(), ..listener };
        assert_eq!(
            talker.entity_token(
                EntityKind::Publisher,
                10,
                "/chatter",
                "std_msgs::msg::dds_::String_",
                STRING_HASH,
                &Qos { reliable: true, transient_local: false, depth: 7 }
            ),
            format!(
                "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
            )
        );
        // a namespace and a nested topic are mangled
        let ns = NodeId { namespace: "/robot1".into(), ..talker };
        assert!(ns.node_token().ends_with("/NN/%/%robot1/talker"), "{}", ns.node_token());
        assert_eq!(mangle("/robot1/odom"), "%robot1%odom");
        // best effort, transient local
        assert_eq!(Qos { reliable: false, transient_local: true, depth: 1 }.keyexpr(), "2:1:,1:,:,:,,");
    }

    /// zenoh-ext 1.x's `AdvancedPublisher`: `KE_ADV_PREFIX / KE_PUB / zid /
    /// eid / KE_EMPTY` under the publisher's key (`@adv`, `pub`, `_`), and
    /// `ke_liveliness` = `${remaining:**}/@adv/${entity:*}/${zid:*}/${eid:*}/${meta:**}`
    /// that subscribers parse it with.
    #[test]
    fn cache_key_as_zenoh_ext_declares_it() {
        let key = topic_key(0, "/tf_static", "tf2_msgs::msg::dds_::TFMessage_", "RIHS01_e369");
        assert_eq!(
            cache_key(&key, "8b20917502ee955ac4476e0266340d5c", 5),
            "0/tf_static/tf2_msgs::msg::dds_::TFMessage_/RIHS01_e369/@adv/pub/8b20917502ee955ac4476e0266340d5c/5/_"
        );
        // transient local, keep last 1, as /tf_static's token says it
        assert_eq!(Qos { reliable: true, transient_local: true, depth: 1 }.keyexpr(), ":1:,1:,:,:,,");
    }

    #[test]
    fn attachment_is_33_bytes_in_the_documented_order() {
        let a = Attachment {
            sequence_number: 1,
            source_timestamp: 0x0102_0304_0506_0708,
            gid: [0xa0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 0xaf],
        };
        let b = a.encode();
        let want: Vec<u8> = [
            &[1, 0, 0, 0, 0, 0, 0, 0][..],
            &[8, 7, 6, 5, 4, 3, 2, 1],
            &[16],
            &[0xa0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 0xaf],
        ]
        .concat();
        assert_eq!(b.to_vec(), want);
        assert_eq!(Attachment::decode(&b), Ok(a));
        assert_eq!(Attachment::decode(&b[..32]), Err(AttachmentError::Length { len: 32 }));
        let mut bad = b;
        bad[16] = 8;
        assert_eq!(Attachment::decode(&bad), Err(AttachmentError::GidLength { len: 8 }));
    }
}
