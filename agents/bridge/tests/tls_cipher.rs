//! The bridge's TLS cipher, end to end through rustls in memory: a client
//! and a server built on [`nerve_bridge::cipher::provider`] agree on
//! AES-128-GCM, a peer that still prefers ring's default order agrees with
//! it as well, and a 230 KB sample crosses intact. `--ignored` also prints
//! what sealing and opening a 230 KB sample costs per TLS 1.3 suite here
//! (the TLS-only work of the bridge's two ends, without Zenoh or sockets).

use rustls::crypto::CryptoProvider;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer, ServerName};
use rustls::{CipherSuite, ClientConfig, ClientConnection, RootCertStore, ServerConfig, ServerConnection};
use std::io::{Read as _, Write as _};
use std::sync::Arc;

/// The bench's largest payload.
const SAMPLE: usize = 230_400;

fn configs(client: CryptoProvider, server: CryptoProvider) -> (Arc<ClientConfig>, Arc<ServerConfig>) {
    let ck = rcgen::generate_simple_self_signed(vec!["robot-a".to_string()]).expect("a certificate");
    let cert: CertificateDer<'static> = ck.cert.der().clone();
    let key = PrivateKeyDer::Pkcs8(PrivatePkcs8KeyDer::from(ck.signing_key.serialize_der()));
    let mut roots = RootCertStore::empty();
    roots.add(cert.clone()).expect("the root");
    let tls13 = [&rustls::version::TLS13];
    let c = ClientConfig::builder_with_provider(Arc::new(client))
        .with_protocol_versions(&tls13)
        .expect("TLS 1.3")
        .with_root_certificates(roots)
        .with_no_client_auth();
    let s = ServerConfig::builder_with_provider(Arc::new(server))
        .with_protocol_versions(&tls13)
        .expect("TLS 1.3")
        .with_no_client_auth()
        .with_single_cert(vec![cert], key)
        .expect("the key");
    (Arc::new(c), Arc::new(s))
}

/// Moves everything `from` has to send into `to`.
fn pump(from: &mut dyn FlushTls, to: &mut dyn FeedTls) {
    let mut wire = Vec::new();
    while from.wants() {
        from.write_to(&mut wire);
    }
    let mut rd = &wire[..];
    while !rd.is_empty() {
        to.feed(&mut rd);
    }
}

trait FlushTls {
    fn wants(&self) -> bool;
    fn write_to(&mut self, out: &mut Vec<u8>);
}
trait FeedTls {
    fn feed(&mut self, rd: &mut &[u8]);
}
macro_rules! tls_io {
    ($t:ty) => {
        impl FlushTls for $t {
            fn wants(&self) -> bool {
                self.wants_write()
            }
            fn write_to(&mut self, out: &mut Vec<u8>) {
                self.write_tls(out).expect("write_tls");
            }
        }
        impl FeedTls for $t {
            fn feed(&mut self, rd: &mut &[u8]) {
                self.read_tls(rd).expect("read_tls");
                self.process_new_packets().expect("a valid record");
            }
        }
    };
}
tls_io!(ClientConnection);
tls_io!(ServerConnection);

/// A connected pair: the negotiated suite, and the two ends.
fn connect(client: CryptoProvider, server: CryptoProvider) -> (CipherSuite, ClientConnection, ServerConnection) {
    let (cc, sc) = configs(client, server);
    let mut c = ClientConnection::new(cc, ServerName::try_from("robot-a").expect("a name")).expect("client");
    let mut s = ServerConnection::new(sc).expect("server");
    for _ in 0..8 {
        if !c.is_handshaking() && !s.is_handshaking() {
            break;
        }
        pump(&mut c, &mut s);
        pump(&mut s, &mut c);
    }
    assert!(!c.is_handshaking() && !s.is_handshaking(), "the handshake ends");
    let suite = c.negotiated_cipher_suite().expect("a suite").suite();
    assert_eq!(Some(suite), s.negotiated_cipher_suite().map(|x| x.suite()));
    (suite, c, s)
}

/// One sample from client to server: sealed in records, opened, read out.
/// (rustls takes up to 64 KB of plaintext at a time, as Zenoh's batches
/// are, and holds a bounded amount of received plaintext: read as it comes)
fn send_sample(c: &mut ClientConnection, s: &mut ServerConnection, sample: &[u8], into: &mut [u8]) {
    let (mut sent, mut got) = (0, 0);
    let mut wire = Vec::new();
    for _ in 0..10_000 {
        if got == into.len() {
            return;
        }
        if sent < sample.len() {
            sent += c.writer().write(&sample[sent..]).expect("plaintext in");
        }
        wire.clear();
        while c.wants_write() {
            c.write_tls(&mut wire).expect("write_tls");
        }
        let mut rd = &wire[..];
        while !rd.is_empty() {
            s.read_tls(&mut rd).expect("read_tls");
            s.process_new_packets().expect("a valid record");
            loop {
                match s.reader().read(&mut into[got..]) {
                    Ok(0) => break,
                    Ok(n) => got += n,
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(e) => panic!("reading the plaintext: {e}"),
                }
            }
        }
    }
    panic!("{got} of {} bytes crossed", into.len());
}

fn ring_only(suite: rustls::SupportedCipherSuite) -> CryptoProvider {
    CryptoProvider { cipher_suites: vec![suite], ..rustls::crypto::ring::default_provider() }
}

#[test]
fn the_bridges_agree_on_aes_128_and_a_sample_crosses_intact() {
    let (suite, mut c, mut s) = connect(nerve_bridge::cipher::provider(), nerve_bridge::cipher::provider());
    assert_eq!(suite, CipherSuite::TLS13_AES_128_GCM_SHA256);
    let sample: Vec<u8> = (0..SAMPLE).map(|i| (i % 251) as u8).collect();
    let mut got = vec![0u8; SAMPLE];
    send_sample(&mut c, &mut s, &sample, &mut got);
    assert!(got == sample, "the sample crossed intact");
}

#[test]
fn a_peer_with_rings_default_order_still_connects() {
    // the client's order decides (rustls servers follow it by default)
    let (suite, ..) = connect(rustls::crypto::ring::default_provider(), nerve_bridge::cipher::provider());
    assert_eq!(suite, CipherSuite::TLS13_AES_256_GCM_SHA384, "an older bridge dialling in");
    let (suite, ..) = connect(nerve_bridge::cipher::provider(), rustls::crypto::ring::default_provider());
    assert_eq!(suite, CipherSuite::TLS13_AES_128_GCM_SHA256, "dialling an older bridge");
}

/// `cargo test -p nerve-bridge --release --test tls_cipher -- --ignored --nocapture`
#[test]
#[ignore = "a measurement: prints µs per 230 KB sample and suite"]
fn what_a_230_kb_sample_costs_per_suite() {
    let sample: Vec<u8> = (0..SAMPLE).map(|i| (i % 251) as u8).collect();
    let mut got = vec![0u8; SAMPLE];
    for suite in rustls::crypto::ring::default_provider().cipher_suites.into_iter().filter(|s| s.tls13().is_some()) {
        let (name, mut c, mut s) = connect(ring_only(suite), ring_only(suite));
        let mut per: Vec<f64> = Vec::new();
        for _ in 0..7 {
            let t = std::time::Instant::now();
            for _ in 0..200 {
                send_sample(&mut c, &mut s, &sample, &mut got);
            }
            per.push(t.elapsed().as_secs_f64() * 1e6 / 200.0);
        }
        per.sort_by(f64::total_cmp);
        println!(
            "{name:?}: {:.1} µs per sample sealed and opened (median of 7 x 200; {:.1}-{:.1})",
            per[3], per[0], per[6]
        );
    }
}
