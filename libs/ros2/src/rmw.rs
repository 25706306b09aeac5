//! rmw_zenoh's wire conventions, so a Zenoh session can be a ROS 2 node to
//! ROS 2 nodes on `rmw_zenoh_cpp`: data keys, liveliness tokens, QoS strings,
//! the attachment every sample and request carries, and the RIHS01 type
//! hashes that key expressions name.
//!
//! Read from rmw_zenoh_cpp 0.2.10 (Jazzy) and 0.1.9 (Humble), whose sources
//! win where `docs/design.md` differs: `liveliness_utils.cpp` (keys, tokens,
//! QoS), `attachment_helpers.cpp` (the attachment), `rmw_publisher_data.cpp`
//! and `rmw_service_data.cpp` (what a publisher and a service do).
//!
//! ```text
//! data     0/robot_6665/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_64c1…d828
//! node     @ros2_lv/0/<zid>/3/3/NN/%/%robot_6665/amcl
//! entity   @ros2_lv/0/<zid>/3/4/MP/%/%robot_6665/amcl/%robot_6665%amcl_pose/<type>/<hash>/::,10:,:,:,,
//! ```

/// The ROS 2 distribution whose conventions to speak: Jazzy's (and later)
/// name each type's RIHS01 hash in keys and tokens; Humble's has none.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Distro {
    /// Jazzy, Kilted, Rolling: RIHS01 type hashes.
    #[default]
    Jazzy,
    /// Humble (rmw_zenoh's backport): `TypeHashNotSupported` in the hash's place.
    Humble,
}

impl std::fmt::Display for Distro {
    /// Its flag's value: `jazzy` or `humble`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Distro::Jazzy => "jazzy",
            Distro::Humble => "humble",
        })
    }
}

/// A distribution name Troupe does not know.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown ROS 2 distribution `{0}` (jazzy, kilted, rolling or humble)")]
pub struct UnknownDistro(pub String);

impl std::str::FromStr for Distro {
    type Err = UnknownDistro;
    fn from_str(s: &str) -> Result<Self, UnknownDistro> {
        match s.to_ascii_lowercase().as_str() {
            "jazzy" | "kilted" | "rolling" => Ok(Distro::Jazzy),
            "humble" => Ok(Distro::Humble),
            other => Err(UnknownDistro(other.to_owned())),
        }
    }
}

/// What Humble writes where a type hash goes.
pub const NO_TYPE_HASH: &str = "TypeHashNotSupported";

/// The RIHS01 hash (REP-2011) of each ROS 2 type Troupe speaks, Jazzy's
/// definitions. Regenerate and cross-check (rosbags against
/// ros2_pyterfaces, and both against design.md's `std_msgs/msg/String`):
///
/// ```sh
/// python3 -m venv /tmp/rihs && /tmp/rihs/bin/pip install rosbags==0.11.9 ros2_pyterfaces==0.3.0
/// /tmp/rihs/bin/python libs/ros2/hashes.py
/// ```
///
/// rosbags has no services (GetMap is ros2_pyterfaces' and the script's
/// own REP-2011 hasher's) and ros2_pyterfaces no tf2_msgs (TFMessage is
/// rosbags', rebuilt by the script from ros2_pyterfaces' TransformStamped).
pub const TYPE_HASHES: &[(&str, &str)] = &[
    (
        "std_msgs/msg/String",
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    ),
    (
        "sensor_msgs/msg/LaserScan",
        "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    ),
    (
        "sensor_msgs/msg/Range",
        "RIHS01_b42b62562e93cbfe9d42b82fe5994dfa3d63d7d5c90a317981703f7388adff3a",
    ),
    (
        "sensor_msgs/msg/Image",
        "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47",
    ),
    (
        "sensor_msgs/msg/CompressedImage",
        "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a",
    ),
    (
        "nav_msgs/msg/Odometry",
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    ),
    (
        "nav_msgs/msg/OccupancyGrid",
        "RIHS01_8d348150c12913a31ee0ec170fbf25089e4745d17035792a1ba94d6f0bc0cfc7",
    ),
    (
        "nav_msgs/msg/Path",
        "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b",
    ),
    (
        "geometry_msgs/msg/PoseWithCovarianceStamped",
        "RIHS01_26432f9803e43727d3c8f668d1fdb3c630f548af631e2f4e31382371bfea3b6e",
    ),
    (
        "geometry_msgs/msg/PoseArray",
        "RIHS01_af0cc36d190e104d546d168d6b39df04fa4b4ccecf59cb4c9ed328d3d5004aa0",
    ),
    (
        "geometry_msgs/msg/PoseStamped",
        "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
    ),
    (
        "geometry_msgs/msg/Twist",
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    ),
    (
        "tf2_msgs/msg/TFMessage",
        "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087",
    ),
    (
        "rosgraph_msgs/msg/Clock",
        "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564",
    ),
    (
        "nav_msgs/srv/GetMap",
        "RIHS01_c8ae77c9995b3554b5ba80e4d4d443f970ac65143102a1d893ec24fc07b31147",
    ),
];

/// The hash `distro` names type `ty` (`sensor_msgs/msg/LaserScan`) by;
/// `None` for a type not in [`TYPE_HASHES`].
pub fn type_hash(ty: &str, distro: Distro) -> Option<&'static str> {
    let hash = TYPE_HASHES.iter().find(|(t, _)| *t == ty)?.1;
    Some(match distro {
        Distro::Jazzy => hash,
        Distro::Humble => NO_TYPE_HASH,
    })
}

/// A type's name as rmw_zenoh writes it: `sensor_msgs::msg::dds_::LaserScan_`
/// for `sensor_msgs/msg/LaserScan` (a service's, `nav_msgs::srv::dds_::GetMap_`).
pub fn dds_type_name(ty: &str) -> String {
    let mut parts = ty.rsplitn(2, '/');
    let name = parts.next().unwrap_or(ty);
    let ns = parts.next().unwrap_or("").replace('/', "::");
    format!("{ns}::dds_::{name}_")
}

/// The key of a topic's samples (or a service's queries): the domain, the
/// fully qualified name without its outer slashes, the type and its hash.
/// `0/robot_6665/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_…`.
pub fn topic_key(domain: u32, fqn: &str, ty: &str, hash: &str) -> String {
    let name = fqn.strip_prefix('/').unwrap_or(fqn);
    let name = name.strip_suffix('/').unwrap_or(name);
    format!("{domain}/{name}/{}/{hash}", dds_type_name(ty))
}

/// A data key's domain, topic and type (`sensor_msgs/msg/LaserScan`), if
/// it has rmw_zenoh's form: `0/robot_6665/scan/sensor_msgs::msg::dds_::LaserScan_/RIHS01_…`
/// is `(0, "/robot_6665/scan", "sensor_msgs/msg/LaserScan")`.
pub fn parse_key(key: &str) -> Option<(u32, String, String)> {
    let mut parts: Vec<&str> = key.split('/').collect();
    if parts.len() < 4 {
        return None;
    }
    let _hash = parts.pop()?;
    let dds = parts.pop()?;
    let domain = parts[0].parse().ok()?;
    let (ns, name) = dds.split_once("::dds_::")?;
    let name = name.strip_suffix('_')?;
    if ns.is_empty() || name.is_empty() || parts[1..].iter().any(|p| p.is_empty()) {
        return None;
    }
    Some((
        domain,
        format!("/{}", parts[1..].join("/")),
        format!("{}/{name}", ns.replace("::", "/")),
    ))
}

/// A name in a token: every `/` as `%` (`/robot_6665` is `%robot_6665`).
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The QoS rmw_zenoh keys by: what Troupe's endpoints use of it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// RELIABLE (else BEST_EFFORT).
    pub reliable: bool,
    /// TRANSIENT_LOCAL (else VOLATILE): late subscribers get the last samples.
    pub transient_local: bool,
    /// KEEP_LAST's depth.
    pub depth: usize,
}

impl Qos {
    /// Reliable, volatile, keep the last 10: rclcpp's default for topics.
    pub const DEFAULT: Qos = Qos {
        reliable: true,
        transient_local: false,
        depth: 10,
    };
    /// Reliable, transient local, keep the last one: a map, `/tf_static`.
    pub const LATCHED: Qos = Qos {
        reliable: true,
        transient_local: true,
        depth: 1,
    };
    /// A service's endpoints: rmw's services default (keep last 10, reliable, volatile).
    pub const SERVICES: Qos = Qos::DEFAULT;

    /// rmw_zenoh's `qos_to_keyexpr`: reliability, durability, history and
    /// depth, deadline, lifespan, liveliness and its lease, each written
    /// only where it differs from rmw_zenoh's own default (keep last 42,
    /// reliable, volatile, infinite, automatic). `::,10:,:,:,,` for
    /// [`Qos::DEFAULT`].
    pub fn to_keyexpr(self) -> String {
        let rel = if self.reliable { "" } else { "2" };
        let dur = if self.transient_local { "1" } else { "" };
        let depth = if self.depth == 42 {
            String::new()
        } else {
            self.depth.to_string()
        };
        format!("{rel}:{dur}:,{depth}:,:,:,,")
    }
}

/// An entity's kind in its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A message publisher.
    Publisher,
    /// A message subscription.
    Subscription,
    /// A service server.
    Service,
    /// A service client.
    Client,
}

impl Kind {
    fn code(self) -> &'static str {
        match self {
            Kind::Publisher => "MP",
            Kind::Subscription => "MS",
            Kind::Service => "SS",
            Kind::Client => "SC",
        }
    }
}

/// A ROS 2 node as its tokens name it: on one Zenoh session (`zid`, as
/// `ZenohId`'s `Display` writes it), numbered `nid` among that session's
/// entities.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    /// The ROS domain (`ROS_DOMAIN_ID`).
    pub domain: u32,
    /// The Zenoh session's id.
    pub zid: String,
    /// Its number among the session's entities.
    pub nid: u64,
    /// `/robot_6665`, or `/`.
    pub namespace: String,
    /// `amcl`.
    pub name: String,
}

/// The enclave rcl gives a node that names none.
const ENCLAVE: &str = "/";

impl Node {
    fn prefix(&self, eid: u64) -> String {
        format!("@ros2_lv/{}/{}/{}/{eid}", self.domain, self.zid, self.nid)
    }

    fn names(&self) -> String {
        format!(
            "{}/{}/{}",
            mangle(ENCLAVE),
            mangle(&self.namespace),
            self.name
        )
    }

    /// The node's own token: `@ros2_lv/0/<zid>/<nid>/<nid>/NN/%/%/<name>`.
    pub fn token(&self) -> String {
        format!("{}/NN/{}", self.prefix(self.nid), self.names())
    }

    /// An entity's token: `…/<eid>/MP/%/<ns>/<node>/<topic>/<type>/<hash>/<qos>`.
    pub fn entity_token(
        &self,
        eid: u64,
        kind: Kind,
        fqn: &str,
        ty: &str,
        hash: &str,
        qos: Qos,
    ) -> String {
        format!(
            "{}/{}/{}/{}/{}/{hash}/{}",
            self.prefix(eid),
            kind.code(),
            self.names(),
            mangle(fqn),
            dds_type_name(ty),
            qos.to_keyexpr()
        )
    }
}

/// An entity's GID as rmw_zenoh makes it: the XXH3-128 of its token, its
/// low 64 bits first, each half little-endian.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// What every rmw_zenoh sample, request and reply carries beside its
/// payload (rmw_zenoh's subscribers drop a sample without it): the
/// sequence number of the publisher's samples (from 1), the source time
/// (wall clock, nanoseconds since the epoch) and the publisher's GID, as
/// zenoh-ext's serializer writes them: two little-endian `i64`s, the GID's
/// length (16, a one-byte LEB128) and its bytes. 33 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// The sample's number, from 1.
    pub seq: i64,
    /// When it was sent, nanoseconds since the Unix epoch.
    pub stamp_ns: i64,
    /// The sender's GID.
    pub gid: [u8; 16],
}

/// An attachment's length in bytes.
pub const ATTACHMENT_LEN: usize = 33;

impl Attachment {
    /// The attachment's bytes.
    pub fn to_bytes(&self) -> [u8; ATTACHMENT_LEN] {
        let mut b = [0u8; ATTACHMENT_LEN];
        b[..8].copy_from_slice(&self.seq.to_le_bytes());
        b[8..16].copy_from_slice(&self.stamp_ns.to_le_bytes());
        b[16] = 16;
        b[17..].copy_from_slice(&self.gid);
        b
    }

    /// Reads an attachment; `None` unless it has exactly that form.
    pub fn parse(b: &[u8]) -> Option<Attachment> {
        if b.len() != ATTACHMENT_LEN || b[16] != 16 {
            return None;
        }
        let i64_at = |i: usize| b.get(i..i + 8).and_then(|s| s.try_into().ok());
        Some(Attachment {
            seq: i64::from_le_bytes(i64_at(0)?),
            stamp_ns: i64::from_le_bytes(i64_at(8)?),
            gid: b[17..].try_into().ok()?,
        })
    }
}

/// Nanoseconds since the Unix epoch, now (the attachment's source time).
pub fn wall_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    // design.md's examples, exactly.
    const ZID: &str = "8b20917502ee955ac4476e0266340d5c";
    const STRING_HASH: &str =
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";

    #[test]
    fn keys_are_design_md_s() {
        assert_eq!(
            topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH),
            format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        assert_eq!(
            topic_key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH),
            format!("0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
        );
        assert_eq!(
            dds_type_name("nav_msgs/srv/GetMap"),
            "nav_msgs::srv::dds_::GetMap_"
        );
        assert_eq!(
            type_hash("std_msgs/msg/String", Distro::Jazzy),
            Some(STRING_HASH)
        );
        assert_eq!(
            type_hash("sensor_msgs/msg/LaserScan", Distro::Humble),
            Some("TypeHashNotSupported")
        );
        assert_eq!(type_hash("foo_msgs/msg/Bar", Distro::Jazzy), None);
    }

    #[test]
    fn keys_read_back() {
        let key = topic_key(
            0,
            "/robot_6665/scan",
            "sensor_msgs/msg/LaserScan",
            "RIHS01_x",
        );
        assert_eq!(
            parse_key(&key),
            Some((
                0,
                "/robot_6665/scan".into(),
                "sensor_msgs/msg/LaserScan".into()
            ))
        );
        assert_eq!(
            parse_key("3/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported"),
            Some((3, "/chatter".into(), "std_msgs/msg/String".into()))
        );
        for not in [
            "robot/6665/laser/0",
            "sim/clock",
            "0//a::dds_::B_/h",
            "x/t/a::dds_::B_/h",
        ] {
            assert_eq!(parse_key(not), None, "{not}");
        }
    }

    #[test]
    fn every_type_troupe_writes_has_its_hash() {
        for ty in crate::Type::ALL {
            assert!(
                type_hash(ty.name(), Distro::Jazzy).is_some(),
                "{}",
                ty.name()
            );
        }
    }

    #[test]
    fn tokens_are_design_md_s() {
        let listener = Node {
            domain: 0,
            zid: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
            nid: 0,
            namespace: "/".into(),
            name: "listener".into(),
        };
        assert_eq!(
            listener.token(),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
        );
        let talker = Node {
            zid: ZID.into(),
            name: "talker".into(),
            ..listener
        };
        let qos = Qos {
            depth: 7,
            ..Qos::DEFAULT
        };
        assert_eq!(
            talker.entity_token(10, Kind::Publisher, "/chatter", "std_msgs/msg/String", STRING_HASH, qos),
            format!("@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,")
        );
        let ns = Node {
            namespace: "/robot_6665".into(),
            ..talker
        };
        assert!(ns
            .entity_token(3, Kind::Service, "/robot_6665/map_server/map", "nav_msgs/srv/GetMap", "h", Qos::SERVICES)
            .starts_with(&format!("@ros2_lv/0/{ZID}/0/3/SS/%/%robot_6665/talker/%robot_6665%map_server%map/nav_msgs::srv::dds_::GetMap_/h/")));
    }

    #[test]
    fn qos_strings_are_rmw_zenoh_s() {
        assert_eq!(Qos::DEFAULT.to_keyexpr(), "::,10:,:,:,,");
        assert_eq!(Qos::LATCHED.to_keyexpr(), ":1:,1:,:,:,,");
        let best_effort = Qos {
            reliable: false,
            ..Qos::DEFAULT
        };
        assert_eq!(best_effort.to_keyexpr(), "2::,10:,:,:,,");
        let default_depth = Qos {
            depth: 42,
            ..Qos::DEFAULT
        };
        assert_eq!(default_depth.to_keyexpr(), "::,:,:,:,,");
    }

    #[test]
    fn gid_is_xxh3_128_of_the_token_low_half_first() {
        // Python's xxhash: xxh3_128(token).intdigest().to_bytes(16, 'little').
        assert_eq!(hex(&gid("")), "7f498d4624c30160d8984701d306aa99");
        let token = format!("@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,");
        assert_eq!(token.len(), 184);
        assert_eq!(hex(&gid(&token)), "eb85fa883b7846dc448a4501890ad062");
        // Past 240 bytes XXH3 takes its long path.
        assert_eq!(
            hex(&gid(&token.repeat(2))),
            "a4a863c08c3d7903a2835cdfd6ea668f"
        );
    }

    #[test]
    fn the_attachment_is_33_bytes_as_zenoh_ext_serializes_it() {
        let a = Attachment {
            seq: 1,
            stamp_ns: 0x0102_0304_0506_0708,
            gid: [0xab; 16],
        };
        let b = a.to_bytes();
        let mut want = vec![1, 0, 0, 0, 0, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, 16];
        want.extend([0xab; 16]);
        assert_eq!(b.to_vec(), want);
        assert_eq!(Attachment::parse(&b), Some(a));
        assert_eq!(Attachment::parse(&b[..32]), None);
        let mut bad = b;
        bad[16] = 15;
        assert_eq!(Attachment::parse(&bad), None);
    }

    #[test]
    fn distros_parse() {
        assert_eq!("Humble".parse::<Distro>(), Ok(Distro::Humble));
        assert_eq!("rolling".parse::<Distro>(), Ok(Distro::Jazzy));
        assert!("foxy"
            .parse::<Distro>()
            .unwrap_err()
            .to_string()
            .contains("humble"));
        for d in [Distro::Jazzy, Distro::Humble] {
            assert_eq!(d.to_string().parse::<Distro>(), Ok(d));
        }
    }

    fn hex(b: &[u8]) -> String {
        b.iter().map(|x| format!("{x:02x}")).collect()
    }
}
