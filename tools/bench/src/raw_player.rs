//! A Player client in raw XDR over a plain socket, as libplayerc speaks
//! (no TCP_NODELAY, PULL mode): the benches' client of the bridge.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

use troupe_bridge::wire::{self, player, Header, HEADER_LEN};
use troupe_bridge::xdr::Writer;
use troupe_msgs::Interface;

pub(crate) const ROBOT: u32 = troupe_msgs::DEFAULT_ROBOT;

/// The header of request `subtype` to `interf`:0 of the bench's robot.
pub(crate) fn req(interf: Interface, subtype: u32) -> [u32; 6] {
    let code = u32::from(interf.code());
    [0, ROBOT, code, 0, u32::from(wire::REQ), subtype]
}

/// A Player message header from its six leading fields.
pub(crate) fn header(h: [u32; 6]) -> Header {
    let [host, robot, interf, index, kind, subtype] = h;
    Header {
        host,
        robot,
        interf,
        index,
        kind,
        subtype,
        ..Header::default()
    }
}

/// The next message from the bridge.
pub(crate) fn next(s: &mut TcpStream) -> anyhow::Result<(Header, Vec<u8>)> {
    let mut hdr = [0u8; HEADER_LEN];
    s.read_exact(&mut hdr)?;
    let got = Header::read(&hdr)?;
    let mut b = vec![0; got.size as usize];
    s.read_exact(&mut b)?;
    Ok((got, b))
}

/// A Player client's side of a request, in raw XDR over a socket without
/// TCP_NODELAY, as libplayerc: send, then read until the answer (DATA ahead
/// of it is read and dropped, as the client queues it).
pub(crate) fn request(s: &mut TcpStream, h: [u32; 6], body: &[u8]) -> anyhow::Result<Vec<u8>> {
    let [_, _, interf, _, _, subtype] = h;
    s.write_all(&wire::message(header(h), body))?;
    loop {
        let (got, b) = next(s)?;
        match u8::try_from(got.kind) {
            Ok(wire::RESP_ACK) if (got.interf, got.subtype) == (interf, subtype) => return Ok(b),
            Ok(wire::RESP_NACK) => anyhow::bail!("request {h:?} refused"),
            _ => {}
        }
    }
}

/// The `player` device's request `sub`.
pub(crate) fn player_req(sub: u8) -> [u32; 6] {
    [
        0,
        0,
        u32::from(wire::PLAYER_CODE),
        0,
        u32::from(wire::REQ),
        u32::from(sub),
    ]
}

/// A client past the banner, in PULL mode as libplayerc puts itself.
pub(crate) fn connect(addr: SocketAddr) -> anyhow::Result<TcpStream> {
    let mut s = TcpStream::connect(addr)?;
    // A request the bridge leaves unanswered fails the bench, not hangs it.
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut banner = [0u8; wire::BANNER_LEN];
    s.read_exact(&mut banner)?;
    request(
        &mut s,
        player_req(player::REQ_DATAMODE),
        &player::PULL.to_be_bytes(),
    )?;
    Ok(s)
}

pub(crate) fn open(s: &mut TcpStream, interf: Interface) -> anyhow::Result<()> {
    open_at(s, interf, 0)
}

pub(crate) fn open_at(s: &mut TcpStream, interf: Interface, index: u32) -> anyhow::Result<()> {
    let mut body = Writer::new();
    for v in [0, 0, u32::from(interf.code()), index, player::OPEN] {
        body.u32(v);
    }
    // An empty driver name.
    body.bytes(&[]);
    request(s, player_req(player::REQ_DEV), &body.finish()).map(drop)
}

/// What one `Read()` in PULL mode brought.
pub(crate) struct Round {
    /// Some DATA came before the SYNCH.
    pub data: bool,
    /// The SYNCH said data was dropped.
    pub overflow: bool,
}

/// One `Read()` in PULL mode, as libplayerc's `playerc_client_read`: REQ
/// DATA, then everything up to the SYNCH.
pub(crate) fn pull_round(s: &mut TcpStream) -> anyhow::Result<Round> {
    s.write_all(&wire::message(header(player_req(player::REQ_DATA)), &[]))?;
    let mut data = false;
    loop {
        let (h, _) = next(s)?;
        match u8::try_from(h.kind) {
            Ok(wire::DATA) => data = true,
            Ok(wire::SYNCH) => {
                let overflow = h.subtype == u32::from(player::SYNCH_OVERFLOW);
                return Ok(Round { data, overflow });
            }
            _ => {}
        }
    }
}
