//! Property tests of what the page's requests carry, under generated input
//! (issue 40, "every decoder of outside bytes"); the head of a request
//! (`http::parse_head`) has its own generated-input test in `http.rs`:
//!
//! * the target's query (`split_url`, `percent_decode`): arbitrary text
//!   never panics, the path is the target's part before `?`, there are no
//!   more pairs than `&`-separated parts, a decoded text is never more than
//!   three times as long as the input (each byte at most one U+FFFD), and
//!   percent-encoded text decodes to itself;
//! * the action body (`Action` from JSON): arbitrary bytes and mutated
//!   valid bodies are an action or an error, never a panic, and an action
//!   that parses writes back to JSON that parses to the same action.
//!
//! The default case count is proptest's (256, or `PROPTEST_CASES`); the long
//! run is in `docs/robustness.md`.

use super::{percent_decode, query, split_url};
use crate::action::Action;
use proptest::prelude::*;

/// Every byte of `s` as `%XX`.
fn percent_encode(s: &str) -> String {
    s.bytes().map(|b| format!("%{b:02X}")).collect()
}

/// A body of the page's actions, with generated fields.
fn action_json() -> impl Strategy<Value = String> {
    let op = proptest::sample::select(
        &[
            "connect",
            "disconnect",
            "rate",
            "suspend",
            "resume",
            "stop",
            "kill",
            "restart",
            "params",
            "param_get",
            "param_set",
            "start",
            "nope",
        ][..],
    );
    let field = proptest::sample::select(&["from", "to", "name", "period", "key", "value", "kind", "extra"][..]);
    (op, proptest::collection::vec((field, ".{0,16}"), 0..5)).prop_map(|(op, fields)| {
        let mut m = serde_json::Map::new();
        m.insert("op".into(), op.into());
        for (k, v) in fields {
            m.insert(k.into(), v.into());
        }
        serde_json::Value::Object(m).to_string()
    })
}

/// Parses `bytes` as an action: an error, or an action that round-trips.
fn check_action(bytes: &[u8]) -> Result<(), TestCaseError> {
    if let Ok(a) = serde_json::from_slice::<Action>(bytes) {
        let again = serde_json::to_vec(&a).map_err(|e| TestCaseError::fail(e.to_string()))?;
        let back: Action = serde_json::from_slice(&again).map_err(|e| TestCaseError::fail(e.to_string()))?;
        prop_assert_eq!(back, a);
    }
    Ok(())
}

proptest! {
    // no regression files in the source tree: a failure prints its input
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    /// Arbitrary targets: see the module documentation.
    #[test]
    fn proptest_ui_query_arbitrary(url in "\\PC{0,256}", key in "[a-z]{0,4}") {
        let (path, pairs) = split_url(&url);
        prop_assert_eq!(path, url.split('?').next().unwrap_or(""));
        let parts = url.split_once('?').map_or(0, |(_, q)| q.split('&').count());
        prop_assert!(pairs.len() <= parts);
        for (k, v) in &pairs {
            prop_assert!(k.len() + v.len() <= 3 * url.len());
        }
        let _ = query(&pairs, &key);
        prop_assert!(percent_decode(&url).len() <= 3 * url.len());
    }

    /// Percent-encoded text decodes to itself, as a query value too.
    #[test]
    fn proptest_ui_query_round_trip(key in "[a-z]{1,8}", value in "\\PC{0,64}") {
        prop_assert_eq!(percent_decode(&percent_encode(&value)), value.clone());
        let url = format!("/api/samples?{key}={}&other=1", percent_encode(&value));
        let (path, pairs) = split_url(&url);
        prop_assert_eq!(path, "/api/samples");
        prop_assert_eq!(query(&pairs, &key), Some(value.as_str()));
    }

    /// Arbitrary action bodies, generated ones, and those with a byte
    /// changed or cut.
    #[test]
    fn proptest_ui_action_body(
        bytes in proptest::collection::vec(any::<u8>(), 0..256),
        json in action_json(),
        at in any::<prop::sample::Index>(),
        with in any::<u8>(),
        cut in any::<prop::sample::Index>(),
    ) {
        check_action(&bytes)?;
        check_action(json.as_bytes())?;
        let mut changed = json.clone().into_bytes();
        let i = at.index(changed.len());
        changed[i] = with;
        check_action(&changed)?;
        check_action(&json.as_bytes()[..cut.index(json.len())])?;
    }
}
