//! Mutual TLS 1.3 for QUIC against the cluster CA.
//!
//! Both sides authenticate: the server requires a client certificate issued by the cluster CA,
//! and the client checks the server's against the same CA. A peer with a certificate from another
//! CA, or with none, fails the handshake, so no byte of its messages ever reaches the decoder.
//!
//! The crypto provider is ring, passed explicitly to every builder rather than taken from the
//! process default: the process default is global state another crate could install or change,
//! and with two providers compiled in rustls refuses to guess.
//!
//! Session resumption and 0-RTT are off. 0-RTT data is replayable and would arrive before the
//! handshake completes; resumption would skip the certificate exchange on reconnects. Peers connect
//! rarely, so a full handshake each time costs nothing that matters.

use std::sync::Arc;

use quinn::crypto::rustls::{NoInitialCipherSuite, QuicClientConfig, QuicServerConfig};
use rustls::client::Resumption;
use rustls::crypto::CryptoProvider;
use rustls::pki_types::CertificateDer;
use rustls::server::{NoServerSessionStorage, VerifierBuilderError, WebPkiClientVerifier};
use rustls::{RootCertStore, version};

use super::certs::PeerIdentity;

/// The application protocol both ends must agree on; a bump here refuses old peers in the
/// handshake instead of confusing them later.
pub const ALPN: &[u8] = b"tessera/1";

/// Why a TLS configuration could not be built from an identity.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// rustls refused the configuration.
    #[error("TLS configuration: {0}")]
    Rustls(#[from] rustls::Error),
    /// The verifier of client certificates could not be built from the CA.
    #[error("client certificate verifier: {0}")]
    Verifier(#[from] VerifierBuilderError),
    /// The TLS configuration lacks the cipher suite QUIC's initial packets need.
    #[error("QUIC needs TLS_AES_128_GCM_SHA256: {0}")]
    Quic(#[from] NoInitialCipherSuite),
}

/// The crypto provider of every configuration here: ring.
pub fn provider() -> Arc<CryptoProvider> {
    Arc::new(rustls::crypto::ring::default_provider())
}

/// The server side: present `identity`'s certificate, require one issued by its CA.
pub fn server_config(identity: &PeerIdentity) -> Result<QuicServerConfig, TlsError> {
    let provider = provider();
    let verifier = WebPkiClientVerifier::builder_with_provider(
        Arc::new(roots(identity.ca())?),
        provider.clone(),
    )
    .build()?;
    let mut config = rustls::ServerConfig::builder_with_provider(provider)
        .with_protocol_versions(&[&version::TLS13])?
        .with_client_cert_verifier(verifier)
        .with_single_cert(vec![identity.cert().clone()], identity.key())?;
    config.alpn_protocols = vec![ALPN.to_vec()];
    config.session_storage = Arc::new(NoServerSessionStorage {});
    config.send_tls13_tickets = 0;
    // QUIC allows only 0 (no 0-RTT) or u32::MAX here; 0 is rustls's default, kept on purpose.
    config.max_early_data_size = 0;
    Ok(QuicServerConfig::try_from(config)?)
}

/// The client side: present `identity`'s certificate, accept only servers issued by its CA.
pub fn client_config(identity: &PeerIdentity) -> Result<QuicClientConfig, TlsError> {
    let mut config = rustls::ClientConfig::builder_with_provider(provider())
        .with_protocol_versions(&[&version::TLS13])?
        .with_root_certificates(roots(identity.ca())?)
        .with_client_auth_cert(vec![identity.cert().clone()], identity.key())?;
    config.alpn_protocols = vec![ALPN.to_vec()];
    config.resumption = Resumption::disabled();
    config.enable_early_data = false;
    Ok(QuicClientConfig::try_from(config)?)
}

/// A root store holding the cluster CA alone.
pub(crate) fn roots(ca: &CertificateDer<'static>) -> Result<RootCertStore, rustls::Error> {
    let mut roots = RootCertStore::empty();
    roots.add(ca.clone())?;
    Ok(roots)
}
