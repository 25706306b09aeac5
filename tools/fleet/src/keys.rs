//! `troupe fleet-keys`: a fleet's certificates and each host's Zenoh config.
//!
//! One certificate authority per fleet; each identity (the router, a host
//! that runs robots' drivers, an operator, a viewer) gets a key and a
//! certificate whose common name is its name, and a Zenoh config that
//! holds them (base64, so the one file works wherever it is mounted):
//! TLS only, mutual authentication, scouting off. Each member also has a
//! user name and password (Zenoh's usrpwd authentication), which the
//! router checks against the `passwords` file beside its config: Zenoh's
//! TLS has no revocation list, so deleting a member's line there (and
//! restarting the router) is how a lost host is shut out without
//! re-keying the fleet. Zenoh does the rest; Troupe adds no security
//! mechanism of its own.

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
    /// Hosts that run drivers, each with the robots whose keys it serves
    /// (`robot1:6665`, `sim:6665:6666`): it may publish, answer requests and
    /// declare devices under `robot/<port>/**` of those robots only, and
    /// ask them. Repeatable or comma-separated.
    #[arg(
        long = "hosts",
        value_name = "NAME:PORT…",
        value_delimiter = ',',
        required = true
    )]
    pub hosts: Vec<String>,
    /// Operators: may command and ask the robots named (`ops:6665`), or
    /// every robot (`ops`), and see everything.
    #[arg(long = "operators", value_name = "NAME[:PORT…]", value_delimiter = ',')]
    pub operators: Vec<String>,
    /// Viewers: may subscribe, list and read devices' latest data and maps,
    /// and never command.
    #[arg(long = "viewers", value_name = "NAME", value_delimiter = ',')]
    pub viewers: Vec<String>,
    /// The router's name: the address every host connects to (tls/NAME:7447),
    /// and the name its certificate is checked against.
    #[arg(long, value_name = "NAME", default_value = "router")]
    pub router: String,
    /// Days the certificates are valid.
    #[arg(long, value_name = "N", default_value_t = 365)]
    pub days: u32,
    /// The fleet's Zenoh namespace: every member's config joins it (as
    /// `--namespace` would) and the router's rules name keys under it.
    #[arg(long, value_name = "NS")]
    pub namespace: Option<String>,
}

/// Where the fleet meets: the router's name and the fleet's namespace.
#[derive(Debug, Clone, Copy)]
pub struct Fleet<'a> {
    /// The router's name, which members connect to (tls/NAME:7447).
    pub router: &'a str,
    /// The namespace every key lives under, if any.
    pub namespace: Option<&'a str>,
}

/// An identity of the fleet and what it may do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Member {
    /// Its name: the certificate's common name.
    pub name: String,
    /// What it is.
    pub kind: Kind,
    /// The robots it serves or commands; empty = every robot (operators).
    pub robots: Vec<u32>,
}

/// The kinds of identity.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Runs drivers for its robots.
    Host,
    /// Commands robots.
    Operator,
    /// Looks.
    Viewer,
}

impl Kind {
    /// As a config's metadata names it.
    fn name(self) -> &'static str {
        match self {
            Kind::Host => "host",
            Kind::Operator => "operator",
            Kind::Viewer => "viewer",
        }
    }
}

fn member(spec: &str, kind: Kind) -> anyhow::Result<Member> {
    let mut parts = spec.trim().split(':');
    let name = parts.next().unwrap_or("").to_owned();
    check_name(&name)?;
    let robots = parts
        .map(|p| {
            p.parse::<u32>()
                .with_context(|| format!("`{spec}`: `{p}` is not a robot port (NAME:6665:6666)"))
        })
        .collect::<anyhow::Result<Vec<u32>>>()?;
    match kind {
        Kind::Host if robots.is_empty() => {
            anyhow::bail!("host `{name}` serves no robot: name its robots' ports, e.g. {name}:6665")
        }
        Kind::Viewer if !robots.is_empty() => {
            anyhow::bail!("viewer `{name}` needs no ports: a viewer sees every robot")
        }
        _ => {}
    }
    Ok(Member { name, kind, robots })
}

/// `troupe fleet-keys`.
pub fn fleet_keys(a: KeysArgs) -> anyhow::Result<()> {
    check_name(&a.router)?;
    if let Some(ns) = &a.namespace {
        // Zenoh's own check: a namespace is a key expression without wildcards.
        troupe_node::ZenohArgs {
            namespace: Some(ns.clone()),
            ..Default::default()
        }
        .config(troupe_node::Mode::Client)
        .map_err(|e| anyhow::anyhow!("--namespace {ns}: {e}"))?;
    }
    let fleet = Fleet {
        router: &a.router,
        namespace: a.namespace.as_deref(),
    };
    let mut members = Vec::new();
    for (list, kind) in [
        (&a.hosts, Kind::Host),
        (&a.operators, Kind::Operator),
        (&a.viewers, Kind::Viewer),
    ] {
        for spec in list {
            members.push(member(spec, kind)?);
        }
    }
    for (i, m) in members.iter().enumerate() {
        if m.name == a.router || members[..i].iter().any(|o| o.name == m.name) {
            anyhow::bail!(
                "`{}` is named twice: every identity needs its own name",
                m.name
            );
        }
    }
    std::fs::create_dir_all(&a.dir).with_context(|| format!("creating {}", a.dir.display()))?;
    let ca = Authority::new(a.days)?;
    write(&a.dir.join("ca.pem"), &ca.cert.pem(), false)?;
    write(&a.dir.join("ca-key.pem"), &ca.key.serialize_pem(), true)?;
    let router_cfg = ca
        .identity(&a.router, a.days)?
        .config(&ca, Role::Router(&members), fleet);
    write(
        &a.dir.join(format!("{}.json5", a.router)),
        &router_cfg,
        true,
    )?;
    let names: Vec<&str> = members.iter().map(|m| m.name.as_str()).collect();
    let mut dictionary = String::new();
    for m in &members {
        let (h, password) = (&m.name, password()?);
        let cfg = ca
            .identity(h, a.days)?
            .config(&ca, Role::Member(&password, m.kind), fleet);
        write(&a.dir.join(format!("{h}.json5")), &cfg, true)?;
        dictionary.push_str(&format!("{h}:{password}\n"));
    }
    write(&a.dir.join(PASSWORDS), &dictionary, true)?;
    let mut out = std::io::stdout().lock();
    writeln!(
        out,
        "wrote {}: ca.pem (the fleet's authority; its key ca-key.pem stays here), {}.json5 and {PASSWORDS} for the router, and {} for the hosts",
        a.dir.display(),
        a.router,
        names.iter().map(|h| format!("{h}.json5")).collect::<Vec<_>>().join(", ")
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

/// For `troupe bench latency --secure`: an authority, a router config and
/// the config of `pong`, a host of `robot`; their paths.
pub fn bench_configs(dir: &Path, robot: u32) -> anyhow::Result<(PathBuf, PathBuf)> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let ca = Authority::new(1)?;
    let members = [Member {
        name: "pong".into(),
        kind: Kind::Host,
        robots: vec![robot],
    }];
    let (router, pong) = (dir.join("router.json5"), dir.join("pong.json5"));
    let fleet = Fleet {
        router: "localhost",
        namespace: None,
    };
    let cfg = ca
        .identity("router", 1)?
        .config(&ca, Role::Router(&members), fleet);
    write(&router, &cfg, true)?;
    let password = password()?;
    let cfg = ca
        .identity("pong", 1)?
        .config(&ca, Role::Member(&password, Kind::Host), fleet);
    write(&pong, &cfg, true)?;
    write(&dir.join(PASSWORDS), &format!("pong:{password}\n"), true)?;
    Ok((router, pong))
}

/// The router's user/password dictionary, beside its config (whose
/// relative paths Troupe takes from the config's directory).
pub const PASSWORDS: &str = "passwords";

/// A fresh password: 128 random bits, in hex.
fn password() -> anyhow::Result<String> {
    use std::io::Read as _;
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .context("reading /dev/urandom for a password")?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
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

/// Whose config is written.
#[derive(Debug, Clone, Copy)]
pub enum Role<'a> {
    /// The router: it listens for the fleet, checks each member's password
    /// and enforces what each member may do.
    Router(&'a [Member]),
    /// A member, with its password and its kind: it connects to the router.
    Member(&'a str, Kind),
}

/// Zenoh's access control for the router: deny by default; every member
/// may be sent what it asked for and may watch (subscribe, list, read the
/// latest data and maps); hosts may publish, serve and declare devices
/// under their robots' keys only, and ask them; operators may command and
/// ask their robots. A rule's flow is seen from the router: ingress is
/// what a member sends. Keys are as they travel: under `namespace`.
pub fn access_control(members: &[Member], namespace: Option<&str>) -> serde_json::Value {
    use serde_json::json;
    let all = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "declare_queryable",
        "reply",
        "liveliness_token",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ];
    let ns = |key: &str| match namespace {
        Some(ns) => format!("{ns}/{key}"),
        None => key.to_owned(),
    };
    let robots = |m: &Member, tail: &str| -> Vec<String> {
        if m.robots.is_empty() {
            vec![ns(&format!("robot/*/{tail}"))]
        } else {
            m.robots
                .iter()
                .map(|r| ns(&format!("robot/{r}/{tail}")))
                .collect()
        }
    };
    let (everything, reads) = (
        [ns("robot/**"), ns("sim/**")],
        [
            ns("robot/*/*/*"),
            ns("robot/*/map/*/req/**"),
            ns("robot/*/simulation/*/req/world"),
            ns("robot/*/planner/*/req/waypoints"),
            ns("robot/*/localize/*/req/particles"),
        ],
    );
    let mut rules = vec![
        json!({ "id": "deliver", "flows": ["egress"], "permission": "allow",
                "messages": all, "key_exprs": everything }),
        json!({ "id": "watch", "flows": ["ingress"], "permission": "allow",
                "messages": ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query"],
                "key_exprs": everything }),
        json!({ "id": "read", "flows": ["ingress"], "permission": "allow",
                "messages": ["query"], "key_exprs": reads }),
    ];
    let mut subjects = Vec::new();
    let mut policies = Vec::new();
    for m in members {
        // Both must match: the certificate's name and the user's.
        subjects
            .push(json!({ "id": m.name, "cert_common_names": [m.name], "usernames": [m.name] }));
        let mut own = vec!["deliver".to_owned(), "watch".to_owned(), "read".to_owned()];
        match m.kind {
            Kind::Host => {
                let mut keys = robots(m, "**");
                keys.push(ns("sim/**"));
                rules.push(json!({ "id": format!("serve-{}", m.name), "flows": ["ingress"],
                    "permission": "allow",
                    "messages": ["put", "delete", "declare_queryable", "reply", "liveliness_token", "query"],
                    "key_exprs": keys }));
                own.push(format!("serve-{}", m.name));
            }
            Kind::Operator => {
                let mut keys = robots(m, "*/*/cmd/**");
                keys.extend(robots(m, "*/*/req/**"));
                rules.push(
                    json!({ "id": format!("command-{}", m.name), "flows": ["ingress"],
                    "permission": "allow", "messages": ["put", "query"], "key_exprs": keys }),
                );
                own.push(format!("command-{}", m.name));
            }
            Kind::Viewer => {}
        }
        policies.push(json!({ "rules": own, "subjects": [m.name] }));
    }
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

/// The fleet's certificate authority.
pub struct Authority {
    cert: rcgen::Certificate,
    key: KeyPair,
}

/// A key and the certificate the authority gave it.
pub struct Identity {
    name: String,
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
        // Named by its key: two fleets' authorities never share a name, so
        // a certificate's issuer says which one signed it.
        let id: String = key.public_key_raw()[1..9]
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        p.distinguished_name
            .push(DnType::CommonName, format!("Troupe fleet authority {id}"));
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
        let now = time::OffsetDateTime::now_utc();
        self.identity_between(
            name,
            now - time::Duration::days(1),
            now + time::Duration::days(i64::from(days)),
        )
    }

    /// A certificate for `name` valid from `from` to `to`.
    pub fn identity_between(
        &self,
        name: &str,
        from: time::OffsetDateTime,
        to: time::OffsetDateTime,
    ) -> anyhow::Result<Identity> {
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
        p.not_before = from;
        p.not_after = to;
        let cert = p
            .signed_by(&key, &self.cert, &self.key)
            .with_context(|| format!("signing {name}'s certificate"))?;
        Ok(Identity {
            name: name.to_owned(),
            cert,
            key,
        })
    }
}

fn b64(pem: &str) -> String {
    base64::engine::general_purpose::STANDARD.encode(pem.as_bytes())
}

impl Identity {
    /// This identity's Zenoh config: TLS only, both ends authenticated by
    /// the fleet's authority, members by their password too, no scouting.
    pub fn config(&self, ca: &Authority, role: Role<'_>, fleet: Fleet<'_>) -> String {
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
        let usrpwd;
        match role {
            Role::Router(members) => {
                tls["listen_certificate_base64"] = cert.into();
                tls["listen_private_key_base64"] = key.into();
                c["mode"] = "router".into();
                c["listen"] = serde_json::json!({ "endpoints": ["tls/[::]:7447"] });
                c["access_control"] = access_control(members, fleet.namespace);
                usrpwd = serde_json::json!({ "dictionary_file": PASSWORDS });
            }
            Role::Member(password, kind) => {
                tls["connect_certificate_base64"] = cert.into();
                tls["connect_private_key_base64"] = key.into();
                // A client of the router, listening nowhere: every link is
                // the authenticated one to the router.
                c["mode"] = "client".into();
                c["connect"] =
                    serde_json::json!({ "endpoints": [format!("tls/{}:7447", fleet.router)] });
                if let Some(ns) = fleet.namespace {
                    c["namespace"] = ns.into();
                }
                c["listen"] = serde_json::json!({ "endpoints": [] });
                usrpwd = serde_json::json!({ "user": self.name, "password": password });
                // Who this is, for tools to read (`troupe view` offers no
                // commands to a viewer); the router's rules are what bind.
                c["metadata"] = serde_json::json!({
                    "troupe": { "identity": self.name, "kind": kind.name() }
                });
            }
        }
        c["transport"] =
            serde_json::json!({ "link": { "tls": tls }, "auth": { "usrpwd": usrpwd } });
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
    use troupe_node::viewer_of;

    const FLEET: Fleet<'static> = Fleet {
        router: "router",
        namespace: None,
    };

    #[test]
    fn a_host_config_is_a_zenoh_config_with_tls_only() {
        let c = member_config("robot1", Kind::Host);
        assert_eq!(
            c.get_json("connect/endpoints").unwrap(),
            r#"["tls/router:7447"]"#
        );
        assert_eq!(
            c.get_json("transport/link/tls/enable_mtls").unwrap(),
            "true"
        );
        assert_eq!(c.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(viewer_of(&metadata(&c)), None, "a host is no viewer");
    }

    #[test]
    fn a_viewer_s_config_says_it_is_one() {
        let c = member_config("eye", Kind::Viewer);
        assert_eq!(viewer_of(&metadata(&c)).as_deref(), Some("eye"));
        assert_eq!(
            viewer_of(&metadata(&troupe_node::zenoh::Config::default())),
            None
        );
    }

    /// The config `fleet-keys` writes for member `name`, as Zenoh reads it.
    fn member_config(name: &str, kind: Kind) -> troupe_node::zenoh::Config {
        let ca = Authority::new(30).unwrap();
        let text = ca
            .identity(name, 30)
            .unwrap()
            .config(&ca, Role::Member("secret", kind), FLEET);
        let path = std::env::temp_dir().join(format!("troupe-{name}-{}.json5", std::process::id()));
        std::fs::write(&path, &text).unwrap();
        let c = troupe_node::zenoh::Config::from_file(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        c
    }

    /// A config's `metadata`.
    fn metadata(c: &troupe_node::zenoh::Config) -> serde_json::Value {
        serde_json::from_str(&c.get_json("metadata").unwrap()).unwrap()
    }

    #[test]
    fn the_router_s_config_carries_an_access_policy_zenoh_accepts() {
        let ca = Authority::new(30).unwrap();
        let members = [
            member("robot1:6665", Kind::Host).unwrap(),
            member("ops", Kind::Operator).unwrap(),
            member("eye", Kind::Viewer).unwrap(),
        ];
        let text = ca
            .identity("router", 30)
            .unwrap()
            .config(&ca, Role::Router(&members), FLEET);
        let path = std::env::temp_dir().join(format!("troupe-acl-{}.json5", std::process::id()));
        std::fs::write(&path, &text).unwrap();
        let c = troupe_node::zenoh::Config::from_file(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(
            c.get_json("access_control/default_permission").unwrap(),
            r#""deny""#
        );
        let acl = access_control(&members, None).to_string();
        assert!(
            acl.contains(r#""key_exprs":["robot/6665/**","sim/**"]"#),
            "{acl}"
        );
        assert!(
            acl.contains(r#""key_exprs":["robot/*/*/*/cmd/**","robot/*/*/*/req/**"]"#),
            "{acl}"
        );
        assert!(
            acl.contains(r#"{"rules":["deliver","watch","read"],"subjects":["eye"]}"#),
            "{acl}"
        );
        let acl = access_control(&members, Some("lab")).to_string();
        assert!(
            acl.contains(r#""key_exprs":["lab/robot/6665/**","lab/sim/**"]"#),
            "{acl}"
        );
    }

    /// A config whose certificate is out of date, or from another
    /// authority, is refused before any link is tried, naming the file.
    #[test]
    fn bad_certificates_are_named_with_their_file() {
        let (ca, other) = (Authority::new(30).unwrap(), Authority::new(30).unwrap());
        let now = time::OffsetDateTime::now_utc();
        let expired = ca
            .identity_between(
                "old",
                now - time::Duration::days(60),
                now - time::Duration::days(30),
            )
            .unwrap()
            .config(&ca, Role::Member("secret", Kind::Host), FLEET);
        let foreign = other.identity("stray", 30).unwrap().config(
            &ca,
            Role::Member("secret", Kind::Host),
            FLEET,
        );
        let good =
            ca.identity("good", 30)
                .unwrap()
                .config(&ca, Role::Member("secret", Kind::Host), FLEET);
        for (name, text, want) in [
            (
                "expired",
                expired,
                Some("this host's certificate (CN=old) expired on"),
            ),
            (
                "foreign",
                foreign,
                Some("not by this config's authority `CN=Troupe fleet authority "),
            ),
            ("good", good, None),
        ] {
            let path =
                std::env::temp_dir().join(format!("troupe-{name}-{}.json5", std::process::id()));
            std::fs::write(&path, text).unwrap();
            let r = troupe_node::ZenohArgs {
                zenoh_config: Some(path.clone()),
                ..Default::default()
            }
            .config(troupe_node::Mode::Client);
            let _ = std::fs::remove_file(&path);
            match want {
                None => assert!(r.is_ok(), "{name}: {:?}", r.err()),
                Some(w) => {
                    let e = r.err().map(|e| e.to_string()).unwrap_or_default();
                    assert!(e.contains(w), "{name}: {e}");
                    assert!(e.contains(&path.display().to_string()), "{name}: {e}");
                }
            }
        }
    }

    #[test]
    fn members_are_read_with_their_robots() {
        assert_eq!(
            member("sim:6665:6666", Kind::Host).unwrap().robots,
            [6665, 6666]
        );
        let e = member("robot1", Kind::Host).unwrap_err().to_string();
        assert!(e.contains("serves no robot"), "{e}");
        let e = member("robot1:x", Kind::Host).unwrap_err().to_string();
        assert!(e.contains("`x` is not a robot port"), "{e}");
    }

    #[test]
    fn names_must_be_host_names() {
        assert!(check_name("robot-1.lab").is_ok());
        let e = check_name("robot 1").unwrap_err();
        assert!(e.to_string().contains("cannot name a host"), "{e}");
    }
}
