//! `troupe fleet-keys`: a fleet's certificates and each host's Zenoh config.
//!
//! One certificate authority per fleet; each identity (the router, a host
//! that runs robots' drivers, an operator, a viewer) gets a key and a
//! certificate whose common name is its name, and a Zenoh config that
//! holds them (base64, so the one file works wherever it is mounted):
//! TLS only, mutual authentication, scouting off. Zenoh does the rest;
//! Troupe adds no security mechanism of its own.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Context;
use base64::Engine as _;
use clap::Args;
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, KeyPair,
    KeyUsagePurpose,
};

/// Flags of `troupe fleet-keys`.
#[derive(Debug, Args)]
pub struct KeysArgs {
    /// Directory to write into (created; existing files of the same names are replaced).
    pub dir: PathBuf,
    /// Identities to make, besides the router: a host that runs drivers
    /// (`robot1`), repeatable or comma-separated.
    #[arg(
        long = "hosts",
        value_name = "NAME,…",
        value_delimiter = ',',
        required = true
    )]
    pub hosts: Vec<String>,
    /// The router's name: the address every host connects to (tls/NAME:7447),
    /// and the name its certificate is checked against.
    #[arg(long, value_name = "NAME", default_value = "router")]
    pub router: String,
    /// Days the certificates are valid.
    #[arg(long, value_name = "N", default_value_t = 365)]
    pub days: u32,
}

/// `troupe fleet-keys`.
pub fn fleet_keys(a: KeysArgs) -> anyhow::Result<()> {
    for h in a.hosts.iter().chain([&a.router]) {
        check_name(h)?;
    }
    if a.hosts.contains(&a.router) {
        anyhow::bail!(
            "`{}` is the router's name; give the hosts other names",
            a.router
        );
    }
    std::fs::create_dir_all(&a.dir).with_context(|| format!("creating {}", a.dir.display()))?;
    let ca = Authority::new(a.days)?;
    write(&a.dir.join("ca.pem"), &ca.cert.pem(), false)?;
    write(&a.dir.join("ca-key.pem"), &ca.key.serialize_pem(), true)?;
    let router_cfg = ca
        .identity(&a.router, a.days)?
        .config(&ca, Role::Router, &a.router);
    write(
        &a.dir.join(format!("{}.json5", a.router)),
        &router_cfg,
        true,
    )?;
    for h in &a.hosts {
        let cfg = ca.identity(h, a.days)?.config(&ca, Role::Host, &a.router);
        write(&a.dir.join(format!("{h}.json5")), &cfg, true)?;
    }
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "wrote {}: ca.pem (the fleet's authority; its key ca-key.pem stays here), {}.json5 for the router, and {} for the hosts",
        a.dir.display(),
        a.router,
        a.hosts.iter().map(|h| format!("{h}.json5")).collect::<Vec<_>>().join(", ")
    )?;
    writeln!(
        out,
        "run: troupe --zenoh-config {}/{}.json5 router   and on each host: troupe --zenoh-config {}/HOST.json5 launch …",
        a.dir.display(),
        a.router,
        a.dir.display()
    )?;
    Ok(())
}

/// A name that can be a certificate's common name and a DNS name.
fn check_name(n: &str) -> anyhow::Result<()> {
    let ok = !n.is_empty()
        && n.len() <= 63
        && n.bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'.')
        && !n.starts_with(['-', '.']);
    if ok {
        Ok(())
    } else {
        anyhow::bail!("`{n}` cannot name a host: use letters, digits, `-` and `.`")
    }
}

fn write(p: &Path, text: &str, secret: bool) -> anyhow::Result<()> {
    use std::os::unix::fs::OpenOptionsExt;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(if secret { 0o600 } else { 0o644 })
        .open(p)
        .with_context(|| format!("writing {}", p.display()))?;
    f.write_all(text.as_bytes())
        .with_context(|| format!("writing {}", p.display()))
}

/// What an identity's config lets it do on the network.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Listens for the fleet.
    Router,
    /// Connects to the router.
    Host,
}

/// The fleet's certificate authority.
pub struct Authority {
    cert: rcgen::Certificate,
    key: KeyPair,
}

/// A key and the certificate the authority gave it.
pub struct Identity {
    cert: rcgen::Certificate,
    key: KeyPair,
}

fn validity(p: &mut CertificateParams, days: u32) {
    let now = time::OffsetDateTime::now_utc();
    p.not_before = now - time::Duration::days(1);
    p.not_after = now + time::Duration::days(i64::from(days));
}

impl Authority {
    /// A new authority, valid for `days`.
    pub fn new(days: u32) -> anyhow::Result<Authority> {
        let key = KeyPair::generate().context("making the authority's key")?;
        let mut p = CertificateParams::new(Vec::<String>::new())?;
        p.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        p.distinguished_name
            .push(DnType::CommonName, "Troupe fleet authority");
        p.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        validity(&mut p, days);
        let cert = p.self_signed(&key).context("signing the authority")?;
        Ok(Authority { cert, key })
    }

    /// A certificate for `name` (its common name and DNS name; also valid
    /// for localhost and 127.0.0.1, for a fleet on one machine).
    pub fn identity(&self, name: &str, days: u32) -> anyhow::Result<Identity> {
        let key = KeyPair::generate().with_context(|| format!("making {name}'s key"))?;
        let mut p = CertificateParams::new(vec![
            name.to_owned(),
            "localhost".to_owned(),
            "127.0.0.1".to_owned(),
        ])?;
        p.distinguished_name.push(DnType::CommonName, name);
        p.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        validity(&mut p, days);
        let cert = p
            .signed_by(&key, &self.cert, &self.key)
            .with_context(|| format!("signing {name}'s certificate"))?;
        Ok(Identity { cert, key })
    }
}

fn b64(pem: &str) -> String {
    base64::engine::general_purpose::STANDARD.encode(pem.as_bytes())
}

impl Identity {
    /// This identity's Zenoh config: TLS only, both ends authenticated by
    /// the fleet's authority, no scouting.
    pub fn config(&self, ca: &Authority, role: Role, router: &str) -> String {
        let (cert, key) = (b64(&self.cert.pem()), b64(&self.key.serialize_pem()));
        let mut tls = serde_json::json!({
            "root_ca_certificate_base64": b64(&ca.cert.pem()),
            "enable_mtls": true,
            "verify_name_on_connect": true,
            "close_link_on_expiration": true,
        });
        let mut c = serde_json::json!({
            "scouting": { "multicast": { "enabled": false }, "gossip": { "enabled": false } },
        });
        match role {
            Role::Router => {
                tls["listen_certificate_base64"] = cert.into();
                tls["listen_private_key_base64"] = key.into();
                c["mode"] = "router".into();
                c["listen"] = serde_json::json!({ "endpoints": ["tls/[::]:7447"] });
            }
            Role::Host => {
                tls["connect_certificate_base64"] = cert.into();
                tls["connect_private_key_base64"] = key.into();
                // A client of the router, listening nowhere: every link is
                // the authenticated one to the router.
                c["mode"] = "client".into();
                c["connect"] = serde_json::json!({ "endpoints": [format!("tls/{router}:7447")] });
                c["listen"] = serde_json::json!({ "endpoints": [] });
            }
        }
        c["transport"] = serde_json::json!({ "link": { "tls": tls } });
        let body = serde_json::to_string_pretty(&c).unwrap_or_default();
        format!(
            "// Written by `troupe fleet-keys`: this host's Zenoh config, with its\n\
             // private key. Keep it readable by this host only.\n{body}\n"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_host_config_is_a_zenoh_config_with_tls_only() {
        let ca = Authority::new(30).unwrap();
        let text = ca
            .identity("robot1", 30)
            .unwrap()
            .config(&ca, Role::Host, "router");
        let path = std::env::temp_dir().join(format!("troupe-keys-{}.json5", std::process::id()));
        std::fs::write(&path, &text).unwrap();
        let c = troupe_node::zenoh::Config::from_file(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            r#"["tls/router:7447"]"#
        );
        assert_eq!(
            c.get_json("transport/link/tls/enable_mtls").unwrap(),
            "true"
        );
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
    }

    #[test]
    fn names_must_be_host_names() {
        assert!(check_name("robot-1.lab").is_ok());
        let e = check_name("robot 1").unwrap_err();
        assert!(e.to_string().contains("cannot name a host"), "{e}");
    }
}
