//! What the page can do to the robot: one request body per action, each
//! carried out through the router as the matching `nerve` command is.

use serde::{Deserialize, Serialize};

/// An action of the page, as the JSON body of `POST /api/action`:
/// `{"op": "connect", "from": "t1/tick", "to": "r1/in"}`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum Action {
    /// `nerve connect FROM TO`
    Connect {
        /// output port, `agent/port`
        from: String,
        /// input port, `agent/port`
        to: String,
    },
    /// `nerve disconnect FROM TO`
    Disconnect {
        /// output port
        from: String,
        /// input port
        to: String,
    },
    /// `nerve rate NAME PERIOD`
    Rate {
        /// agent
        name: String,
        /// `10ms`, `1s`, `100hz`
        period: String,
    },
    /// `nerve suspend NAME`
    Suspend {
        /// agent
        name: String,
    },
    /// `nerve resume NAME`
    Resume {
        /// agent
        name: String,
    },
    /// `nerve stop NAME`
    Stop {
        /// agent
        name: String,
    },
    /// `nerve kill NAME`
    Kill {
        /// agent
        name: String,
    },
    /// A supervised agent is killed and its supervisor starts it again;
    /// another is stopped and started again by its kind and name.
    Restart {
        /// agent
        name: String,
    },
    /// `nerve param list NAME`
    Params {
        /// agent
        name: String,
    },
    /// `nerve param get NAME KEY`
    ParamGet {
        /// agent
        name: String,
        /// parameter
        key: String,
    },
    /// `nerve param set NAME KEY VALUE`
    ParamSet {
        /// agent
        name: String,
        /// parameter
        key: String,
        /// value as text
        value: String,
    },
    /// `nerve start KIND --name NAME` (hot add)
    Start {
        /// agent kind
        kind: String,
        /// name of the new agent
        name: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn actions_read_from_the_page_json() {
        let a: Action = serde_json::from_str(r#"{"op":"connect","from":"t1/tick","to":"r1/in"}"#).expect("parse");
        assert_eq!(a, Action::Connect { from: "t1/tick".into(), to: "r1/in".into() });
        let a: Action =
            serde_json::from_str(r#"{"op":"param_set","name":"t1","key":"step","value":"5"}"#).expect("parse");
        assert_eq!(a, Action::ParamSet { name: "t1".into(), key: "step".into(), value: "5".into() });
        assert!(serde_json::from_str::<Action>(r#"{"op":"explode","name":"t1"}"#).is_err());
        assert!(serde_json::from_str::<Action>(r#"{"op":"kill"}"#).is_err());
        assert!(serde_json::from_str::<Action>(r#"{"op":"kill","name":"a","extra":1}"#).is_err());
    }
}
