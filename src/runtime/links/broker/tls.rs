//! TLS on the embedded broker's listener: the broker's certificate and key from
//! `[mqtt.tls]`, and client certificates required when the vehicle's own link presents one
//! (mosquitto's `certfile`, `keyfile`, `cafile` and `require_certificate`).

use std::sync::Arc;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};
use serde::{Deserialize, Serialize};
use tokio_rustls::TlsAcceptor;

use crate::runtime::error::{RuntimeError, invalid};

/// The broker's side of TLS.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ServerTls {
    /// The broker's certificate chain (PEM).
    pub cert_file: String,
    /// Its private key (PEM).
    pub key_file: String,
    /// When set, clients must present a certificate signed by these CAs (PEM).
    pub client_ca_file: Option<String>,
}

impl ServerTls {
    /// The acceptor for the listener; an error names the file that failed.
    pub fn acceptor(&self) -> Result<TlsAcceptor, RuntimeError> {
        // rustls needs a process-wide crypto provider; ring is the one compiled in.
        let _ = rustls::crypto::ring::default_provider().install_default();
        let certs = CertificateDer::pem_file_iter(&self.cert_file)
            .and_then(|certs| certs.collect::<Result<Vec<_>, _>>())
            .map_err(invalid(format!(
                "mqtt.tls.cert_file: cannot read {}",
                self.cert_file
            )))?;
        if certs.is_empty() {
            return Err(RuntimeError::Failed(format!(
                "mqtt.tls.cert_file: no certificate in {}",
                self.cert_file
            )));
        }
        let key = PrivateKeyDer::from_pem_file(&self.key_file).map_err(invalid(format!(
            "mqtt.tls.key_file: cannot read a key from {}",
            self.key_file
        )))?;
        let builder = rustls::ServerConfig::builder();
        let builder = match &self.client_ca_file {
            Some(ca_file) => {
                let mut roots = rustls::RootCertStore::empty();
                for cert in CertificateDer::pem_file_iter(ca_file)
                    .map_err(invalid(format!("mqtt.tls.ca_file: cannot read {ca_file}")))?
                {
                    let cert =
                        cert.map_err(invalid(format!("mqtt.tls.ca_file: bad PEM in {ca_file}")))?;
                    roots.add(cert).map_err(invalid(format!(
                        "mqtt.tls.ca_file: bad certificate in {ca_file}"
                    )))?;
                }
                let verifier = rustls::server::WebPkiClientVerifier::builder(Arc::new(roots))
                    .build()
                    .map_err(invalid("mqtt.tls.ca_file: cannot verify clients with it"))?;
                builder.with_client_cert_verifier(verifier)
            }
            None => builder.with_no_client_auth(),
        };
        let config = builder.with_single_cert(certs, key).map_err(invalid(
            "mqtt.tls: the certificate and key do not go together",
        ))?;
        Ok(TlsAcceptor::from(Arc::new(config)))
    }
}
