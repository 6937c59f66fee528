//! The link's security in the bridge's configuration: where the files of
//! mutual TLS are (`[tls]`, the fleet's keys directory) and which endpoints
//! this build can use, and which of them stay on this host (plain TCP beyond
//! it needs `insecure = true`). Re-exported by [`crate::config`].

use std::path::PathBuf;

/// The directory of the fleet's keys under the nerve home (`nerve bridge keys`
/// uses the same).
pub const KEYS_DIR_NAME: &str = "bridge-keys";

/// Where `nerve bridge keys` keeps the fleet's keys by default:
/// `$NERVE_HOME/bridge-keys`, else under [`agent_sdk::world::default_home`].
pub fn default_keys_dir() -> PathBuf {
    std::env::var_os(agent_sdk::world::HOME_ENV)
        .filter(|h| !h.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(agent_sdk::world::default_home)
        .join(KEYS_DIR_NAME)
}

/// Where the TLS files are (`[tls]`), before the robot's name is known.
#[derive(Debug, Clone, PartialEq)]
pub struct Tls {
    /// the keys directory (`keys`, else [`default_keys_dir`])
    pub keys: PathBuf,
    /// the fleet CA's certificate, if named one by one
    pub ca: Option<PathBuf>,
    /// this robot's certificate, if named one by one
    pub cert: Option<PathBuf>,
    /// this robot's private key, if named one by one
    pub key: Option<PathBuf>,
}

/// The three files of mutual TLS for one robot.
#[derive(Debug, Clone, PartialEq)]
pub struct TlsFiles {
    /// the fleet CA's certificate (PEM)
    pub ca: PathBuf,
    /// the robot's certificate, signed by the CA, common name = robot (PEM)
    pub cert: PathBuf,
    /// the robot's private key (PEM)
    pub key: PathBuf,
}

impl Tls {
    /// The files of `robot`: named ones, else `KEYS/ca.crt`, `KEYS/<robot>.crt`, `KEYS/<robot>.key`.
    pub fn files(&self, robot: &str) -> TlsFiles {
        TlsFiles {
            ca: self.ca.clone().unwrap_or_else(|| self.keys.join("ca.crt")),
            cert: self.cert.clone().unwrap_or_else(|| self.keys.join(format!("{robot}.crt"))),
            key: self.key.clone().unwrap_or_else(|| self.keys.join(format!("{robot}.key"))),
        }
    }
}

impl TlsFiles {
    /// Says which file is missing or unreadable, and how to make it. With
    /// `robot` `None` (the robot is not known yet: `nerve launch`'s check),
    /// only the files that do not depend on the robot's name.
    pub fn check(&self, robot: Option<&str>, tls: &Tls) -> Result<(), String> {
        let who = robot.unwrap_or("ROBOT");
        let mine = |named: &Option<PathBuf>| robot.is_some() || named.is_some();
        let files = [
            ("the fleet CA certificate", &self.ca, "nerve bridge keys init".to_string(), true),
            ("this robot's certificate", &self.cert, format!("nerve bridge keys add {who}"), mine(&tls.cert)),
            ("this robot's private key", &self.key, format!("nerve bridge keys add {who}"), mine(&tls.key)),
        ];
        for (what, path, make, _) in files.iter().filter(|f| f.3) {
            if let Err(e) = std::fs::File::open(path) {
                return Err(format!(
                    "[tls]: cannot read {what} {}: {e}; make it with `{make}` (with --dir {}), or name the file in [tls]",
                    path.display(),
                    path.parent().map_or_else(String::new, |p| p.display().to_string())
                ));
            }
        }
        Ok(())
    }
}

/// Whether an endpoint's host is a loopback address (`127.0.0.0/8`, `::1`, `localhost`).
pub fn is_loopback_endpoint(ep: &str) -> bool {
    let addr = ep.split_once('/').map_or(ep, |(_, a)| a);
    let addr = addr.split(['?', '#']).next().unwrap_or(addr);
    let host = addr.rsplit_once(':').map_or(addr, |(h, _)| h);
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host == "localhost" || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// An endpoint this build can use: `tcp/HOST:PORT` or `tls/HOST:PORT`.
pub(super) fn check_endpoint(ep: &str) -> Result<(), String> {
    let Some(addr) = ep.strip_prefix("tcp/").or_else(|| ep.strip_prefix("tls/")) else {
        return Err(format!(
            "endpoint {ep:?}: this bridge speaks TCP and TLS only; write tls/HOST:PORT (e.g. tls/10.0.0.2:7447) or tcp/127.0.0.1:PORT"
        ));
    };
    let addr = addr.split(['?', '#']).next().unwrap_or(addr);
    let Some((host, port)) = addr.rsplit_once(':') else {
        return Err(format!("endpoint {ep:?} has no port; write tls/HOST:PORT or tcp/HOST:PORT"));
    };
    if host.is_empty() || port.parse::<u16>().is_err() {
        return Err(format!("endpoint {ep:?}: write tls/HOST:PORT or tcp/HOST:PORT with a port from 0 to 65535"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_are_checked() {
        assert!(check_endpoint("tcp/127.0.0.1:7447").is_ok());
        assert!(check_endpoint("tcp/[::1]:7447").is_ok());
        assert!(check_endpoint("tcp/10.0.0.2:7447#iface=veth0").is_ok());
        assert!(check_endpoint("tcp/127.0.0.1").is_err());
        assert!(check_endpoint("tcp/host:99999").is_err());
        assert!(check_endpoint("quic/127.0.0.1:7447").is_err());
        assert!(check_endpoint("tls/10.0.0.2:7447").is_ok());
        assert!(is_loopback_endpoint("tcp/127.0.0.1:7447") && is_loopback_endpoint("tcp/[::1]:1"));
        assert!(is_loopback_endpoint("tcp/localhost:1") && is_loopback_endpoint("tcp/127.3.0.1:1#iface=lo"));
        assert!(!is_loopback_endpoint("tcp/10.0.0.2:7447") && !is_loopback_endpoint("tcp/0.0.0.0:7447"));
        assert!(!is_loopback_endpoint("tcp/[::]:7447") && !is_loopback_endpoint("tcp/robot2.lan:7447"));
    }
}
