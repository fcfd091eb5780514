//! The cluster's certificates: one certificate authority, and one certificate per peer signed by
//! it.
//!
//! Trust is the cluster CA and nothing else: no system roots, no IP addresses or host names, so a
//! peer may move between machines and addresses and still be recognised. Each peer gets its own
//! key and certificate rather than one shared by all, so that a certificate says *which* peer it
//! belongs to: its subject alternative names are [`ANY_PEER_NAME`] (any member of the cluster) and
//! [`peer_name`]`(K)` (peer K in particular). A connection's identity is thus fixed by the
//! handshake, before any message, and a peer cannot claim another's index.
//!
//! `tessera keygen --out DIR` writes, with [`ClusterCerts::write_pem`]:
//! - `ca.pem`: the CA certificate, needed by every peer;
//! - `ca-key.pem`: the CA's private key, needed by no peer: keep it offline, it only serves to
//!   issue more peer certificates;
//! - `peer-K.pem` and `peer-K-key.pem` for K in `0..N`: peer K's certificate and private key.
//!
//! Keys are ECDSA P-256. Certificates are valid from the first of January of last year (tolerating
//! clock skew between machines) for [`VALIDITY_YEARS`] years.

use std::fmt;
use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose,
};
use rustls::client::{verify_server_cert_signed_by_trust_anchor, verify_server_name};
use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer, PrivatePkcs8KeyDer, ServerName, UnixTime};
use rustls::server::ParsedCertificate;

/// The name every peer certificate carries: "a member of this cluster".
pub const ANY_PEER_NAME: &str = "tessera-peer";

/// How long certificates made by [`ClusterCerts::generate`] are valid.
pub const VALIDITY_YEARS: i32 = 10;

/// The name only peer `index`'s certificate carries.
pub fn peer_name(index: u32) -> String {
    format!("peer-{index}.tessera")
}

/// A cluster's CA and the identities of its peers, as [`ClusterCerts::generate`] made them.
pub struct ClusterCerts {
    ca_pem: String,
    ca_key_pem: String,
    peers: Vec<PeerIdentity>,
    peer_pems: Vec<(String, String)>,
}

/// What one peer needs to take part in the cluster: the CA it trusts, its certificate and key.
pub struct PeerIdentity {
    index: u32,
    ca: CertificateDer<'static>,
    cert: CertificateDer<'static>,
    key: PrivatePkcs8KeyDer<'static>,
}

/// The certificate a connected peer presented, already verified against the cluster CA.
#[derive(Clone, Debug)]
pub struct PeerCertificate(CertificateDer<'static>);

/// Why certificates could not be made, written or loaded.
#[derive(Debug, thiserror::Error)]
pub enum CertError {
    /// rcgen could not make a key or a certificate.
    #[error("generating certificates: {0}")]
    Generate(#[from] rcgen::Error),
    /// A key or certificate file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        source: io::Error,
    },
    /// A file to write is there already, and may be another cluster's only copy of its keys.
    #[error("{}: already exists; refusing to overwrite a cluster's keys", path.display())]
    Exists {
        /// The file.
        path: PathBuf,
    },
    /// A file holds no PEM item of the kind expected.
    #[error("{}: no usable PEM {what}: {problem}", path.display())]
    Pem {
        /// The file.
        path: PathBuf,
        /// The kind of item expected (certificate or key).
        what: &'static str,
        /// What was wrong.
        problem: String,
    },
    /// A peer's certificate does not chain to the cluster's CA.
    #[error("the certificate of peer {index} was not issued by this CA: {problem}")]
    NotIssuedByCa {
        /// The peer's index.
        index: u32,
        /// What the verifier said.
        problem: String,
    },
    /// A peer's certificate is for another peer's name.
    #[error("the certificate of peer {index} does not name {}", peer_name(*index))]
    WrongPeer {
        /// The peer whose certificate it should be.
        index: u32,
    },
    /// The folder searched for this peer's key could not be listed.
    #[error("reading {}", dir.display())]
    ReadDir {
        /// The folder.
        dir: PathBuf,
        /// What the system said.
        #[source]
        source: io::Error,
    },
    /// The folder holds no key of a peer other than the owner's.
    #[error("no peer-K-key.pem (K >= 1) in {}", dir.display())]
    NoPeerKey {
        /// The folder.
        dir: PathBuf,
    },
    /// The folder holds the keys of several peers (`tessera keygen` writes all of them into
    /// one), so which one this process is must be said.
    #[error("{} holds keys of peers {peers:?}: say which with --index", dir.display())]
    SeveralPeerKeys {
        /// The folder.
        dir: PathBuf,
        /// The indices of the peers whose keys it holds, in increasing order.
        peers: Vec<u32>,
    },
}

impl ClusterCerts {
    /// Makes a new CA and `peers` peer identities signed by it, all in memory.
    pub fn generate(peers: u32) -> Result<Self, CertError> {
        let year = current_year();
        let mut ca_params = CertificateParams::new(Vec::<String>::new())?;
        ca_params
            .distinguished_name
            .push(DnType::CommonName, "tessera cluster CA");
        // Path length 0: the CA signs peer certificates, never another CA.
        ca_params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        ca_params.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
        set_validity(&mut ca_params, year);
        let ca_key = KeyPair::generate()?;
        let ca_cert = ca_params.self_signed(&ca_key)?;
        let ca_pem = ca_cert.pem();
        let ca_key_pem = ca_key.serialize_pem();
        let issuer = Issuer::new(ca_params, ca_key);

        let mut identities = Vec::with_capacity(peers as usize);
        let mut peer_pems = Vec::with_capacity(peers as usize);
        for index in 0..peers {
            let mut params =
                CertificateParams::new(vec![ANY_PEER_NAME.to_owned(), peer_name(index)])?;
            params
                .distinguished_name
                .push(DnType::CommonName, format!("tessera peer {index}"));
            params.is_ca = IsCa::ExplicitNoCa;
            params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
            // Every peer is a server to some and a client to others.
            params.extended_key_usages = vec![
                ExtendedKeyUsagePurpose::ServerAuth,
                ExtendedKeyUsagePurpose::ClientAuth,
            ];
            params.use_authority_key_identifier_extension = true;
            set_validity(&mut params, year);
            let key = KeyPair::generate()?;
            let cert = params.signed_by(&key, &issuer)?;
            identities.push(PeerIdentity {
                index,
                ca: ca_cert.der().clone(),
                cert: cert.der().clone(),
                key: PrivatePkcs8KeyDer::from(key.serialize_der()),
            });
            peer_pems.push((cert.pem(), key.serialize_pem()));
        }
        Ok(Self {
            ca_pem,
            ca_key_pem,
            peers: identities,
            peer_pems,
        })
    }

    /// The identity of every peer, by index.
    pub fn peers(&self) -> &[PeerIdentity] {
        &self.peers
    }

    /// Writes the files listed in the module documentation into `dir`, creating it if needed.
    /// Existing files are never overwritten, so a live cluster's keys cannot be lost by mistake;
    /// private keys are readable by their owner only.
    pub fn write_pem(&self, dir: &Path) -> Result<(), CertError> {
        fs::create_dir_all(dir).map_err(|source| CertError::Io {
            path: dir.to_owned(),
            source,
        })?;
        write_new(&dir.join("ca.pem"), &self.ca_pem, false)?;
        write_new(&dir.join("ca-key.pem"), &self.ca_key_pem, true)?;
        for (index, (cert, key)) in self.peer_pems.iter().enumerate() {
            write_new(&dir.join(format!("peer-{index}.pem")), cert, false)?;
            write_new(&dir.join(format!("peer-{index}-key.pem")), key, true)?;
        }
        Ok(())
    }
}

impl PeerIdentity {
    /// Loads peer `index`'s identity from a directory written by [`ClusterCerts::write_pem`], and
    /// checks that its certificate was issued by `ca.pem` for that index.
    pub fn load(dir: &Path, index: u32) -> Result<Self, CertError> {
        let ca = read_pem::<CertificateDer>(&dir.join("ca.pem"), "certificate")?;
        let cert =
            read_pem::<CertificateDer>(&dir.join(format!("peer-{index}.pem")), "certificate")?;
        let key = read_pem::<PrivatePkcs8KeyDer>(
            &dir.join(format!("peer-{index}-key.pem")),
            "PKCS#8 private key",
        )?;
        let identity = Self {
            index,
            ca,
            cert,
            key,
        };
        identity.check()?;
        Ok(identity)
    }

    /// The K of the only `peer-K-key.pem` with K >= 1 in `dir`: the index of a peer whose
    /// folder was given only its own key, so that it need not be told which peer it is. The
    /// owner's key (K = 0) does not count, since peers and owner may share one folder.
    pub fn only_index(dir: &Path) -> Result<u32, CertError> {
        let unreadable = |source| CertError::ReadDir {
            dir: dir.to_owned(),
            source,
        };
        let mut found = Vec::new();
        for entry in fs::read_dir(dir).map_err(unreadable)? {
            let name = entry.map_err(unreadable)?.file_name();
            let name = name.to_string_lossy();
            if let Some(k) = name
                .strip_prefix("peer-")
                .and_then(|n| n.strip_suffix("-key.pem"))
                && let Ok(k) = k.parse::<u32>()
                && k >= 1
            {
                found.push(k);
            }
        }
        found.sort_unstable();
        let dir = dir.to_owned();
        match found.len() {
            1 => Ok(found[0]),
            0 => Err(CertError::NoPeerKey { dir }),
            _ => Err(CertError::SeveralPeerKeys { dir, peers: found }),
        }
    }

    /// This peer's index in the cluster.
    pub fn index(&self) -> u32 {
        self.index
    }

    /// The cluster CA certificate, the only trust root.
    pub fn ca(&self) -> &CertificateDer<'static> {
        &self.ca
    }

    /// This peer's certificate.
    pub fn cert(&self) -> &CertificateDer<'static> {
        &self.cert
    }

    /// This peer's private key.
    pub fn key(&self) -> PrivateKeyDer<'static> {
        PrivateKeyDer::Pkcs8(self.key.clone_key())
    }

    /// Fails unless the certificate chains to the CA and names this peer's index: a clear error at
    /// start-up rather than refused handshakes later.
    fn check(&self) -> Result<(), CertError> {
        let not_issued = |e: rustls::Error| CertError::NotIssuedByCa {
            index: self.index,
            problem: e.to_string(),
        };
        let roots = super::tls::roots(&self.ca).map_err(not_issued)?;
        let parsed = ParsedCertificate::try_from(&self.cert).map_err(not_issued)?;
        let algorithms = super::tls::provider().signature_verification_algorithms.all;
        verify_server_cert_signed_by_trust_anchor(
            &parsed,
            &roots,
            &[],
            UnixTime::now(),
            algorithms,
        )
        .map_err(not_issued)?;
        if !PeerCertificate(self.cert.clone()).certifies(self.index) {
            return Err(CertError::WrongPeer { index: self.index });
        }
        Ok(())
    }
}

impl Clone for PeerIdentity {
    fn clone(&self) -> Self {
        Self {
            index: self.index,
            ca: self.ca.clone(),
            cert: self.cert.clone(),
            key: self.key.clone_key(),
        }
    }
}

impl fmt::Debug for PeerIdentity {
    /// Leaves the private key out of logs.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("PeerIdentity")
            .field("index", &self.index)
            .finish_non_exhaustive()
    }
}

impl PeerCertificate {
    pub(crate) fn new(der: CertificateDer<'static>) -> Self {
        Self(der)
    }

    /// Whether the cluster CA issued this certificate to peer `index`. The chain itself was
    /// verified during the handshake; this checks the name.
    pub fn certifies(&self, index: u32) -> bool {
        let Ok(name) = ServerName::try_from(peer_name(index)) else {
            return false;
        };
        ParsedCertificate::try_from(&self.0)
            .and_then(|parsed| verify_server_name(&parsed, &name))
            .is_ok()
    }

    /// The certificate's DER bytes.
    pub fn der(&self) -> &[u8] {
        &self.0
    }
}

/// Sets the validity window of a new certificate.
fn set_validity(params: &mut CertificateParams, year: i32) {
    params.not_before = rcgen::date_time_ymd(year - 1, 1, 1);
    params.not_after = rcgen::date_time_ymd(year + VALIDITY_YEARS, 1, 1);
}

/// The current year by the system clock.
fn current_year() -> i32 {
    let days = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() / 86_400);
    // 146 097 days make 400 Gregorian years; near New Year this may be a year off, which the
    // margin of a whole year before "now" absorbs.
    1970 + i32::try_from(days * 400 / 146_097).unwrap_or(0)
}

fn write_new(path: &Path, contents: &str, private: bool) -> Result<(), CertError> {
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(if private { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = private;
    let mut file = options.open(path).map_err(|source| match source.kind() {
        io::ErrorKind::AlreadyExists => CertError::Exists {
            path: path.to_owned(),
        },
        _ => CertError::Io {
            path: path.to_owned(),
            source,
        },
    })?;
    file.write_all(contents.as_bytes())
        .map_err(|source| CertError::Io {
            path: path.to_owned(),
            source,
        })
}

fn read_pem<T: PemObject>(path: &Path, what: &'static str) -> Result<T, CertError> {
    let bytes = fs::read(path).map_err(|source| CertError::Io {
        path: path.to_owned(),
        source,
    })?;
    T::from_pem_slice(&bytes).map_err(|e| CertError::Pem {
        path: path.to_owned(),
        what,
        problem: e.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keygen_files_load_back_and_are_never_overwritten() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let cluster = ClusterCerts::generate(3).expect("generating certificates");
        cluster.write_pem(dir.path()).expect("writing PEM files");

        let loaded = PeerIdentity::load(dir.path(), 2).expect("loading peer 2");
        assert_eq!(loaded.index(), 2);
        assert_eq!(loaded.cert(), cluster.peers()[2].cert());
        assert_eq!(loaded.ca(), cluster.peers()[2].ca());
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(dir.path().join("peer-2-key.pem"))
                .expect("the key file exists")
                .permissions()
                .mode();
            assert_eq!(mode & 0o077, 0, "private key readable by others: {mode:o}");
        }

        assert!(matches!(
            cluster.write_pem(dir.path()),
            Err(CertError::Exists { .. })
        ));
        assert!(matches!(
            PeerIdentity::load(dir.path(), 3),
            Err(CertError::Io { .. })
        ));

        // Peer 0's certificate and key under peer 1's name: the certificate does not name peer 1.
        let renamed = tempfile::tempdir().expect("a temporary directory");
        for (from, to) in [
            ("ca.pem", "ca.pem"),
            ("peer-0.pem", "peer-1.pem"),
            ("peer-0-key.pem", "peer-1-key.pem"),
        ] {
            std::fs::copy(dir.path().join(from), renamed.path().join(to)).expect("copying");
        }
        assert!(matches!(
            PeerIdentity::load(renamed.path(), 1),
            Err(CertError::WrongPeer { index: 1 })
        ));

        // Another cluster's CA: peer 0's certificate was not issued by it.
        let foreign = tempfile::tempdir().expect("a temporary directory");
        ClusterCerts::generate(1)
            .expect("generating certificates")
            .write_pem(foreign.path())
            .expect("writing PEM files");
        std::fs::copy(foreign.path().join("ca.pem"), renamed.path().join("ca.pem"))
            .expect("copying");
        for file in ["peer-0.pem", "peer-0-key.pem"] {
            std::fs::copy(dir.path().join(file), renamed.path().join(file)).expect("copying");
        }
        assert!(matches!(
            PeerIdentity::load(renamed.path(), 0),
            Err(CertError::NotIssuedByCa { index: 0, .. })
        ));

        std::fs::write(renamed.path().join("ca.pem"), "not PEM").expect("writing");
        assert!(matches!(
            PeerIdentity::load(renamed.path(), 0),
            Err(CertError::Pem { .. })
        ));
    }

    /// A folder with one peer's key names that peer; the owner's key does not count, and a
    /// folder with several, or none, or that is not there, is an error that says so.
    #[test]
    fn the_only_peer_key_in_a_folder_names_the_peer() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        let touch = |name: &str| std::fs::write(dir.path().join(name), "").expect("writing");
        let index = || PeerIdentity::only_index(dir.path());
        touch("ca.pem");
        touch("peer-0-key.pem");
        touch("peer-x-key.pem");
        let none = index().expect_err("only the owner's key");
        assert!(matches!(none, CertError::NoPeerKey { .. }), "{none}");
        touch("peer-12-key.pem");
        assert_eq!(index().expect("one peer's key"), 12);
        touch("peer-3-key.pem");
        let several = index().expect_err("two peers' keys").to_string();
        assert!(
            several.ends_with("keys of peers [3, 12]: say which with --index"),
            "{several}"
        );
        let missing =
            PeerIdentity::only_index(&dir.path().join("absent")).expect_err("no such folder");
        assert!(matches!(missing, CertError::ReadDir { .. }), "{missing}");
    }
}
