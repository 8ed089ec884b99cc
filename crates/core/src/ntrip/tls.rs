//! TLS to a caster (`ntrips://`): the certificate is checked against this computer's trusted
//! roots (the `ca-certificates` store, read by rustls-native-certs) and, for a caster with a
//! private authority, the certificates of `[ntrip] ca_file`. rustls does the protocol
//! (sans-IO, as the rest of this module); the runtime wraps its connection in it.

use std::path::Path;
use std::sync::Arc;

use rustls::pki_types::CertificateDer;
use rustls::pki_types::pem::PemObject;

/// The client configuration for `ntrips://`, or why there is none. `setting` is how the user
/// names the authority's file (`ntrip.ca_file` in a configuration, `--ca-file` on the
/// command line), so the reason names what they wrote.
pub fn client_config(
    ca_file: Option<&Path>,
    setting: &str,
) -> Result<Arc<rustls::ClientConfig>, String> {
    // rustls needs a process-wide crypto provider; ring is the one compiled in.
    let _ = rustls::crypto::ring::default_provider().install_default();
    let mut roots = rustls::RootCertStore::empty();
    // Certificates of the store that do not parse are left out, as every TLS client does.
    let native = rustls_native_certs::load_native_certs();
    let (added, _) = roots.add_parsable_certificates(native.certs);
    let mut from_file = 0;
    if let Some(file) = ca_file {
        let certs = CertificateDer::pem_file_iter(file)
            .map_err(|e| format!("{setting} {}: cannot read: {e}", file.display()))?;
        for cert in certs {
            let cert = cert.map_err(|e| format!("{setting} {}: bad PEM: {e}", file.display()))?;
            roots
                .add(cert)
                .map_err(|e| format!("{setting} {}: bad certificate: {e}", file.display()))?;
            from_file += 1;
        }
        if from_file == 0 {
            return Err(format!(
                "{setting} {}: no certificate in it (PEM, BEGIN CERTIFICATE)",
                file.display()
            ));
        }
    }
    if added + from_file == 0 {
        return Err(format!(
            "no trusted root certificate to check the caster's with: install the \
             ca-certificates package, or name the caster's authority as {setting}"
        ));
    }
    let config = rustls::ClientConfig::builder()
        .with_root_certificates(roots)
        .with_no_client_auth();
    Ok(Arc::new(config))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_or_empty_authority_file_is_named() {
        let e = client_config(Some(Path::new("/nonexistent/ca.pem")), "--ca-file").unwrap_err();
        assert!(
            e.starts_with("--ca-file /nonexistent/ca.pem: cannot read"),
            "{e}"
        );
        let dir = std::env::temp_dir().join(format!("chassisd-ntrip-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("empty.pem"), "not a certificate\n").unwrap();
        let e = client_config(Some(&dir.join("empty.pem")), "ntrip.ca_file").unwrap_err();
        assert!(e.contains("no certificate"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
