//! Which cipher the bridge's TLS links use.
//!
//! Zenoh's TLS transport (zenoh-link-tls) builds its rustls configurations
//! on the process's default crypto provider, and installs *ring*'s own
//! default only when none is installed yet. That default puts
//! `TLS13_AES_256_GCM_SHA384` first, and both ends of a link then agree on
//! it. A 230 KB sample is 15 records of 16 KB, sealed by one bridge and
//! opened by the other; AES-256 takes 14 rounds per block, AES-128 10.
//!
//! [`prefer_aes_128`] installs *ring*'s provider with the same suites, key
//! exchanges and signature checks, only reordered so that
//! `TLS13_AES_128_GCM_SHA256` comes first. AES-128-GCM is the TLS 1.3 suite
//! every implementation must offer (RFC 8446 §9.1): the certificates, the
//! mutual authentication and the access control are unchanged. A peer that
//! prefers AES-256 (an older bridge, a plain Zenoh peer) still connects:
//! the client's order decides and every suite stays enabled.
//!
//! Measured (`tests/tls_cipher.rs`, `--ignored`: a 230 KB sample sealed
//! and opened in memory, AMD EPYC with VAES): AES-128 145 µs against
//! AES-256 183 µs (medians of three runs, machine loaded), ChaCha20 361 µs.
//! The gain is modest: on this CPU AES-GCM is bound by GHASH and the
//! record copies as much as by the AES rounds.

use rustls::CipherSuite;
use rustls::crypto::CryptoProvider;
use std::sync::Once;

static INSTALL: Once = Once::new();

/// The TLS 1.3 suites in the order this bridge offers them.
pub const PREFERRED: [CipherSuite; 3] = [
    CipherSuite::TLS13_AES_128_GCM_SHA256,
    CipherSuite::TLS13_AES_256_GCM_SHA384,
    CipherSuite::TLS13_CHACHA20_POLY1305_SHA256,
];

/// *ring*'s default provider with [`PREFERRED`] first (then any other
/// suite it has, in its own order).
pub fn provider() -> CryptoProvider {
    let mut p = rustls::crypto::ring::default_provider();
    let rank =
        |s: &rustls::SupportedCipherSuite| PREFERRED.iter().position(|c| *c == s.suite()).unwrap_or(PREFERRED.len());
    // a stable sort: the suites not named keep ring's order after ours
    p.cipher_suites.sort_by_key(rank);
    p
}

/// Makes [`provider`] the process's default, once, before the first TLS
/// session is opened (Zenoh then keeps it). If another part of the process
/// installed a provider first, that one stays and a warning names the
/// suite it prefers.
pub fn prefer_aes_128() {
    INSTALL.call_once(|| {
        if provider().install_default().is_ok() {
            tracing::debug!(first = ?PREFERRED[0], "TLS links prefer AES-128-GCM");
            return;
        }
        let first = CryptoProvider::get_default().and_then(|p| p.cipher_suites.first()).map(|s| s.suite());
        if first != Some(PREFERRED[0]) {
            tracing::warn!(
                ?first,
                "a TLS crypto provider was installed before the bridge's: its links keep that provider's cipher order"
            );
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aes_128_first_and_no_suite_lost() {
        let ours: Vec<CipherSuite> = provider().cipher_suites.iter().map(|s| s.suite()).collect();
        let ring: Vec<CipherSuite> =
            rustls::crypto::ring::default_provider().cipher_suites.iter().map(|s| s.suite()).collect();
        assert_eq!(ours[..3], PREFERRED, "TLS 1.3 suites, AES-128-GCM first");
        let (mut a, mut b) = (ours.clone(), ring);
        a.sort_by_key(|s| u16::from(*s));
        b.sort_by_key(|s| u16::from(*s));
        assert_eq!(a, b, "the same suites as ring's default, only reordered");
    }

    #[test]
    fn installed_once_and_kept() {
        prefer_aes_128();
        prefer_aes_128();
        let p = CryptoProvider::get_default().expect("installed");
        assert_eq!(p.cipher_suites.first().map(|s| s.suite()), Some(PREFERRED[0]));
    }
}
