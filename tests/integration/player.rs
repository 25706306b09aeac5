//! Player 3 messages on the wire, written for the tests independently of the
//! bridge's own codec: the 40-byte XDR header and the body.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};

use troupe_msgs::Device;
use troupe_tests::DEADLINE;

/// `PLAYER_MSGTYPE_DATA`.
pub const DATA: u32 = 1;
/// `PLAYER_MSGTYPE_RESP_ACK`.
pub const RESP_ACK: u32 = 4;
/// `PLAYER_MSGTYPE_SYNCH`.
pub const SYNCH: u32 = 5;
/// `PLAYER_MSGTYPE_RESP_NACK`.
pub const RESP_NACK: u32 = 6;

/// One message.
#[derive(Debug, Clone, Default)]
pub struct Frame {
    /// host, robot, interf, index, type, subtype.
    pub h: [u32; 6],
    /// Header timestamp.
    pub timestamp: f64,
    /// Header sequence number.
    pub seq: u32,
    /// The XDR body (its length is the header's size).
    pub body: Vec<u8>,
}

impl Frame {
    /// A message with a zero timestamp and sequence number.
    pub fn new(h: [u32; 6], body: &[u8]) -> Frame {
        Frame {
            h,
            body: body.to_vec(),
            ..Frame::default()
        }
    }

    /// The message type.
    pub fn kind(&self) -> u32 {
        self.h[4]
    }

    /// The body's XDR double at byte `at`.
    pub fn f64_at(&self, at: usize) -> f64 {
        f64::from_be_bytes(self.body[at..at + 8].try_into().expect("8 bytes"))
    }

    /// The body's XDR unsigned int at byte `at`.
    pub fn u32_at(&self, at: usize) -> u32 {
        u32::from_be_bytes(self.body[at..at + 4].try_into().expect("4 bytes"))
    }

    /// interf, index, type, subtype.
    pub fn sig(&self) -> (u32, u32, u32, u32) {
        (self.h[2], self.h[3], self.h[4], self.h[5])
    }

    /// Header and body as sent.
    pub fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(40 + self.body.len());
        for v in self.h {
            b.extend_from_slice(&v.to_be_bytes());
        }
        b.extend_from_slice(&self.timestamp.to_be_bytes());
        b.extend_from_slice(&self.seq.to_be_bytes());
        b.extend_from_slice(&(self.body.len() as u32).to_be_bytes());
        b.extend_from_slice(&self.body);
        b
    }

    /// Reads one message (the test's deadline is the socket's read timeout).
    pub fn read(s: &mut impl Read) -> Frame {
        let mut h = [0u8; 40];
        s.read_exact(&mut h)
            .expect("reading a header from the bridge");
        let word = |i: usize| u32::from_be_bytes(h[i * 4..i * 4 + 4].try_into().unwrap());
        let mut body = vec![0; word(9) as usize];
        s.read_exact(&mut body)
            .expect("reading a body from the bridge");
        Frame {
            h: [word(0), word(1), word(2), word(3), word(4), word(5)],
            timestamp: f64::from_be_bytes(h[24..32].try_into().unwrap()),
            seq: word(8),
            body,
        }
    }
}

/// Appends a byte array as Player's XDR structs carry one (a name, a
/// property's value): the struct's count, then `xdr_bytes`' count, the
/// bytes and zero padding.
pub fn push_bytes(b: &mut Vec<u8>, bytes: &[u8]) {
    let n = u32::try_from(bytes.len()).expect("a short array");
    b.extend_from_slice(&n.to_be_bytes());
    b.extend_from_slice(&n.to_be_bytes());
    b.extend_from_slice(bytes);
    b.resize(b.len().div_ceil(4) * 4, 0);
}

/// A Player client in raw XDR.
pub struct Player {
    /// The connection, for tests that write raw bytes.
    pub s: TcpStream,
    robot: u32,
    /// The DATA that came while [`Player::reply`] waited, as libplayerc
    /// hands it to its proxies.
    pub seen: Vec<Frame>,
}

impl Player {
    /// Connects to `addr` and reads the banner; messages name robot `robot`.
    pub fn connect(addr: SocketAddr, robot: u32) -> Player {
        let mut s = TcpStream::connect(addr).unwrap();
        s.set_read_timeout(Some(DEADLINE)).unwrap();
        let mut banner = [0u8; 32];
        s.read_exact(&mut banner).unwrap();
        assert!(banner.starts_with(b"Player v.3"));
        Player {
            s,
            robot,
            seen: Vec::new(),
        }
    }

    /// Sends one message to this robot.
    pub fn send(&mut self, interf: u32, index: u32, kind: u32, subtype: u32, body: &[u8]) {
        let m = Frame::new([0, self.robot, interf, index, kind, subtype], body);
        self.s.write_all(&m.encode()).unwrap();
    }

    /// The next message.
    pub fn recv(&mut self) -> Frame {
        Frame::read(&mut self.s)
    }

    /// The next message that is not DATA.
    pub fn reply(&mut self) -> Frame {
        loop {
            let r = self.recv();
            if r.kind() != DATA {
                return r;
            }
            self.seen.push(r);
        }
    }

    /// PLAYER_PLAYER_REQ_DEVLIST: its reply.
    pub fn devlist(&mut self) -> Frame {
        self.send(1, 0, 3, 1, &[]);
        self.reply()
    }

    /// Subscribes to `d` (PLAYER_PLAYER_REQ_DEV, access read/write).
    pub fn open(&mut self, d: Device) {
        assert_eq!(self.dev(d, 1), 1, "opening {d}");
    }

    /// Closes `d` (PLAYER_PLAYER_REQ_DEV, access close).
    pub fn close(&mut self, d: Device) {
        assert_eq!(self.dev(d, 2), 2, "closing {d}");
    }

    /// PLAYER_PLAYER_REQ_DEV with `access`; the access granted.
    fn dev(&mut self, d: Device, access: u32) -> u32 {
        let mut b = Vec::new();
        for v in [
            0u32,
            0,
            u32::from(d.interface.code()),
            d.index,
            access,
            0,
            0,
        ] {
            b.extend_from_slice(&v.to_be_bytes());
        }
        self.send(1, 0, 3, 3, &b);
        let r = self.reply();
        assert_eq!((r.h[4], r.h[5]), (4, 3), "{d}: {r:?}");
        u32::from_be_bytes(r.body[16..20].try_into().expect("an access field"))
    }

    /// A request to `d`; its reply, checked to be for `d`.
    pub fn request(&mut self, d: Device, subtype: u32, body: &[u8]) -> Frame {
        self.send(u32::from(d.interface.code()), d.index, 3, subtype, body);
        let r = self.reply();
        assert_eq!(
            (r.h[2], r.h[3], r.h[5]),
            (u32::from(d.interface.code()), d.index, subtype)
        );
        r
    }
}
