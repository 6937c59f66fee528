//! An agent's `inputs` in a launch file: each input's depth and policy
//! (issue 46, docs/inputs.md), as in
//!
//! ```toml
//! [[agent]]
//! name = "base"
//! kind = "motor"
//! inputs = { cmd = { depth = 64, keep = "all" } }
//! ```
//!
//! checked against the agent's own description (the input exists, depth
//! 1..=256, keep `latest` or `all`), each error at its line, and passed to
//! the agent as `--input NAME:depth=N,keep=WORD`.

use super::Ctx;
use agent_sdk::port::depth::{InputOptions, Keep};
use shm_schemas::control::describe::Description;
use std::collections::BTreeMap;
use toml::Spanned;

/// The `--input` settings of agent `agent` (described by `described`) from
/// its `inputs` table `given`; what is wrong is reported to `cx` at its line.
pub(super) fn inputs_of(
    cx: &mut Ctx,
    agent: &str,
    given: &BTreeMap<String, Spanned<toml::Value>>,
    described: &Description,
) -> Vec<String> {
    let mut settings = Vec::new();
    for (input, v) in given {
        if !described.inputs.iter().any(|p| &p.name == input) {
            let known: Vec<&str> = described.inputs.iter().map(|p| p.name.as_str()).collect();
            let known = if known.is_empty() { "none".to_string() } else { known.join(", ") };
            cx.err(v, format!("agent {agent:?} has no input {input:?} (its inputs: {known}); fix the name"));
            continue;
        }
        match options_of(v.get_ref()) {
            Ok(o) => settings.push(format!("{input}:{}", o.to_text())),
            Err(e) => cx.err(v, format!("input {input:?} of agent {agent:?}: {e}")),
        }
    }
    settings
}

/// One input's `{ depth = N, keep = "latest" | "all" }`.
fn options_of(v: &toml::Value) -> Result<InputOptions, String> {
    let Some(table) = v.as_table() else {
        return Err("write its settings as a table: { depth = 64, keep = \"all\" }".into());
    };
    let mut o = InputOptions::default();
    for (k, v) in table {
        match (k.as_str(), v) {
            ("depth", toml::Value::Integer(n)) => o = InputOptions::new(*n, o.keep).map_err(|e| e.to_string())?,
            ("keep", toml::Value::String(w)) => o.keep = Keep::parse(w).map_err(|e| e.to_string())?,
            ("depth", _) => return Err("depth must be a whole number of samples per source, 1 to 256".into()),
            ("keep", _) => return Err("keep must be \"latest\" or \"all\"".into()),
            (other, _) => return Err(format!("unknown setting {other:?}: an input takes `depth` and `keep`")),
        }
    }
    Ok(o)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<InputOptions, String> {
        let v: toml::Value = toml::from_str(&format!("x = {text}")).expect("toml");
        options_of(&v["x"])
    }

    #[test]
    fn depth_and_keep_are_read() {
        assert_eq!(parse("{ depth = 64, keep = \"all\" }"), Ok(InputOptions { depth: 64, keep: Keep::All }));
        assert_eq!(parse("{ keep = \"all\" }"), Ok(InputOptions { depth: 16, keep: Keep::All }));
        assert_eq!(parse("{ depth = 3 }"), Ok(InputOptions { depth: 3, keep: Keep::Latest }));
    }

    #[test]
    fn bad_values_are_refused_saying_what_to_write() {
        for (bad, says) in [
            ("{ depth = 0 }", "1 to 256"),
            ("{ depth = 257 }", "1 to 256"),
            ("{ depth = -1 }", "1 to 256"),
            ("{ depth = \"64\" }", "whole number"),
            ("{ keep = \"everything\" }", "\"latest\""),
            ("{ keep = 1 }", "\"latest\" or \"all\""),
            ("{ deep = 4 }", "unknown setting"),
            ("64", "as a table"),
        ] {
            let e = parse(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
