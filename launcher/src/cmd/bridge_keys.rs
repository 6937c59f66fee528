//! `nerve bridge keys init` / `nerve bridge keys add ROBOT`: the small fleet
//! certificate authority of the bridge's mutual TLS (issue 40).
//!
//! `init` makes the CA: an ECDSA P-256 key (`ca.key`) and its self-signed
//! certificate (`ca.crt`). `add ROBOT` makes a robot's key (`ROBOT.key`)
//! and a certificate (`ROBOT.crt`) signed by that CA whose common name is the
//! robot's name: the bridge's access control knows a peer by that name.
//! Every file is created with mode 0600 (never widened or narrowed after),
//! in a 0700 directory, and is never overwritten. A robot needs `ca.crt`,
//! `ROBOT.crt` and `ROBOT.key`; `ca.key` stays where certificates are made.
//!
//! The default directory is `$NERVE_HOME/bridge-keys` (the same default as
//! the bridge's `[tls]`, `nerve_bridge::config::default_keys_dir`).

use anyhow::{Context, Result, bail};
use clap::Subcommand;
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair, KeyUsagePurpose,
};
use shm_schemas::RobotName;
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The CA's common name.
const CA_NAME: &str = "nerve fleet CA";

/// `nerve bridge keys ...`
#[derive(Debug, Subcommand)]
pub enum KeysCmd {
    /// Make the fleet's CA (ca.key, ca.crt) in the keys directory.
    Init {
        /// The keys directory (default: $NERVE_HOME/bridge-keys).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
    /// Make ROBOT's key and certificate (ROBOT.key, ROBOT.crt), signed by the fleet's CA.
    Add {
        /// The robot's name (its certificate's common name).
        robot: String,
        /// The keys directory (default: $NERVE_HOME/bridge-keys).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
}

/// The default keys directory: `$NERVE_HOME/bridge-keys`, else under
/// nerve's default home (as `nerve_bridge::config::default_keys_dir`).
pub fn default_dir() -> PathBuf {
    std::env::var_os(agent_sdk::world::HOME_ENV)
        .filter(|h| !h.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(agent_sdk::world::default_home)
        .join("bridge-keys")
}

pub fn keys(cmd: KeysCmd) -> Result<ExitCode> {
    match cmd {
        KeysCmd::Init { dir } => {
            let dir = dir.unwrap_or_else(default_dir);
            init(&dir)?;
            println!(
                "made the fleet CA in {}: ca.crt (give it to every robot) and ca.key (keep it here); next: nerve bridge keys add ROBOT",
                dir.display()
            );
        }
        KeysCmd::Add { robot, dir } => {
            let dir = dir.unwrap_or_else(default_dir);
            add(&dir, &robot)?;
            println!(
                "made {robot}.key and {robot}.crt in {} (common name {robot}); robot {robot} needs them and ca.crt",
                dir.display()
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Writes a new file with mode 0600 (refused if it exists).
fn write_new(path: &Path, text: &str) -> Result<()> {
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)
        .with_context(|| format!("cannot create {}", path.display()))?;
    f.write_all(text.as_bytes()).and_then(|()| f.sync_all()).with_context(|| format!("cannot write {}", path.display()))
}

fn refuse_existing(paths: &[&Path], what: &str) -> Result<()> {
    for p in paths {
        if std::fs::symlink_metadata(p).is_ok() {
            bail!("{} exists already: {what}", p.display());
        }
    }
    Ok(())
}

fn private_dir(dir: &Path) -> Result<()> {
    agent_sdk::world::secure_dir(dir).map_err(|e| anyhow::anyhow!("cannot use keys directory {}: {e}", dir.display()))
}

/// Makes the CA in `dir`.
pub fn init(dir: &Path) -> Result<()> {
    private_dir(dir)?;
    let (key_path, crt_path) = (dir.join("ca.key"), dir.join("ca.crt"));
    refuse_existing(
        &[&key_path, &crt_path],
        "this directory has a fleet CA; every robot's certificate is signed by it, so it is never replaced (remove the directory, or use another --dir, to start a new fleet)",
    )?;
    let key = KeyPair::generate().context("cannot generate the CA's key")?;
    let mut params = CertificateParams::new(Vec::<String>::new()).context("CA certificate parameters")?;
    params.distinguished_name.push(DnType::CommonName, CA_NAME);
    params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign, KeyUsagePurpose::DigitalSignature];
    let cert = params.self_signed(&key).context("cannot sign the CA certificate")?;
    write_new(&key_path, &key.serialize_pem())?;
    write_new(&crt_path, &cert.pem())
}

/// Makes `robot`'s key and certificate in `dir`, signed by the CA there.
pub fn add(dir: &Path, robot: &str) -> Result<()> {
    RobotName::new(robot).map_err(|e| anyhow::anyhow!("{e}"))?;
    let (ca_key_path, ca_crt_path) = (dir.join("ca.key"), dir.join("ca.crt"));
    let read = |p: &Path| {
        std::fs::read_to_string(p).with_context(|| {
            format!(
                "cannot read {}; make the fleet CA first: nerve bridge keys init --dir {}",
                p.display(),
                dir.display()
            )
        })
    };
    let ca_key = KeyPair::from_pem(&read(&ca_key_path)?)
        .with_context(|| format!("{} is not a private key in PEM", ca_key_path.display()))?;
    let issuer = Issuer::from_ca_cert_pem(&read(&ca_crt_path)?, ca_key)
        .with_context(|| format!("{} is not a certificate in PEM", ca_crt_path.display()))?;
    let (key_path, crt_path) = (dir.join(format!("{robot}.key")), dir.join(format!("{robot}.crt")));
    refuse_existing(
        &[&key_path, &crt_path],
        "this robot has a certificate already (remove both files to make new ones)",
    )?;
    let key = KeyPair::generate().context("cannot generate the robot's key")?;
    let mut params = CertificateParams::new(vec![robot.to_string()]).context("robot certificate parameters")?;
    params.distinguished_name.push(DnType::CommonName, robot);
    params.is_ca = IsCa::ExplicitNoCa;
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    // a bridge both accepts peers and dials them
    params.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
    let cert = params.signed_by(&key, &issuer).context("cannot sign the robot's certificate")?;
    write_new(&key_path, &key.serialize_pem())?;
    write_new(&crt_path, &cert.pem())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("nerve-keys-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_fleet_ca_signs_robots_and_nothing_is_overwritten() {
        let d = tmp("fleet");
        init(&d).expect("init");
        add(&d, "r1").expect("add r1");
        add(&d, "r2").expect("add r2");
        for f in ["ca.key", "ca.crt", "r1.key", "r1.crt", "r2.key", "r2.crt"] {
            let m = std::fs::metadata(d.join(f)).expect("file").permissions().mode() & 0o777;
            assert_eq!(m, 0o600, "{f}");
        }
        assert_eq!(std::fs::metadata(&d).expect("dir").permissions().mode() & 0o777, 0o700);
        let crt = std::fs::read_to_string(d.join("r1.crt")).expect("crt");
        assert!(crt.starts_with("-----BEGIN CERTIFICATE-----"), "{crt}");
        let e = init(&d).expect_err("a second CA").to_string();
        assert!(e.contains("ca.key exists already") && e.contains("never replaced"), "{e}");
        let e = add(&d, "r1").expect_err("twice").to_string();
        assert!(e.contains("r1.key exists already"), "{e}");
        let e = add(&d, "R 1").expect_err("bad name").to_string();
        assert!(e.contains("robot"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn add_without_a_ca_says_how_to_make_one() {
        let d = tmp("noca");
        std::fs::create_dir_all(&d).expect("dir");
        let e = format!("{:#}", add(&d, "r1").expect_err("no CA"));
        assert!(e.contains("ca.key") && e.contains("nerve bridge keys init --dir"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
