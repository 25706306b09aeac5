//! Clients of the classic protocol: Lichtblick, older Foxglove Studio and
//! the `@foxglove/ws-protocol` libraries offer only `foxglove.websocket.v1`,
//! which the Foxglove SDK's server refuses (HTTP 400), though it speaks the
//! same protocol under its new name `foxglove.sdk.v1` (the same ops and
//! binary opcodes, as foxglove/ws-protocol's spec defines them; the SDK
//! adds only what classic clients ignore). The SDK has no setting for it,
//! so a front on the public port passes every connection to the SDK's
//! server on loopback, renaming the classic subprotocol in the client's
//! upgrade request and back in the server's answer. A client that offers
//! `foxglove.sdk.v1` passes unchanged, and so does every byte after the
//! handshake.

use std::net::SocketAddr;
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

/// The classic protocol's name.
pub const CLASSIC: &str = "foxglove.websocket.v1";
/// The name the SDK's server takes (not v1.1: its `advertise` is another).
pub const SDK: &str = "foxglove.sdk.v1";

/// The longest handshake head taken.
const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its handshake.
const HEAD_TIMEOUT: Duration = Duration::from_secs(10);

/// Accepts clients on `listener` forever, each passed to `inner`.
pub async fn run(listener: TcpListener, inner: SocketAddr) {
    loop {
        match listener.accept().await {
            Ok((client, from)) => {
                tokio::spawn(async move {
                    if let Err(e) = pass(client, inner).await {
                        tracing::debug!("Foxglove client {from}: {e}");
                    }
                });
            }
            Err(e) => {
                tracing::warn!("accepting a Foxglove client: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        }
    }
}

async fn pass(mut client: TcpStream, inner: SocketAddr) -> std::io::Result<()> {
    client.set_nodelay(true)?;
    let (head, rest) = tokio::time::timeout(HEAD_TIMEOUT, read_head(&mut client))
        .await
        .map_err(|_| std::io::Error::other("no handshake within 10 s"))??;
    let (head, classic) = rename_request(&head);
    let mut server = TcpStream::connect(inner).await?;
    server.set_nodelay(true)?;
    server.write_all(head.as_bytes()).await?;
    server.write_all(&rest).await?;
    let (answer, rest) = read_head(&mut server).await?;
    let answer = if classic {
        rename_answer(&answer)
    } else {
        answer
    };
    client.write_all(answer.as_bytes()).await?;
    client.write_all(&rest).await?;
    tokio::io::copy_bidirectional(&mut client, &mut server).await?;
    Ok(())
}

/// Reads an HTTP head (through its blank line) and what came after it.
async fn read_head(s: &mut TcpStream) -> std::io::Result<(String, Vec<u8>)> {
    let mut buf = Vec::with_capacity(1024);
    let mut chunk = [0u8; 2048];
    loop {
        if let Some(end) = buf.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = buf.split_off(end + 4);
            let head = String::from_utf8(buf)
                .map_err(|_| std::io::Error::other("a handshake that is not text"))?;
            return Ok((head, rest));
        }
        if buf.len() > MAX_HEAD {
            return Err(std::io::Error::other("a handshake head over 16 KB"));
        }
        let n = s.read(&mut chunk).await?;
        if n == 0 {
            return Err(std::io::Error::other("closed during the handshake"));
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

fn is_protocol_header(line: &str) -> Option<(&str, &str)> {
    let (name, value) = line.split_once(':')?;
    name.trim()
        .eq_ignore_ascii_case("sec-websocket-protocol")
        .then_some((name, value))
}

/// The client's upgrade request with `foxglove.websocket.v1` offered as
/// `foxglove.sdk.v1`, unless it offers the SDK's own; and whether it was
/// renamed.
pub fn rename_request(head: &str) -> (String, bool) {
    let offered: Vec<String> = head
        .split("\r\n")
        .filter_map(is_protocol_header)
        .flat_map(|(_, v)| v.split(',').map(|p| p.trim().to_owned()))
        .collect();
    if offered.iter().any(|p| p.starts_with(SDK)) || !offered.iter().any(|p| p == CLASSIC) {
        return (head.to_owned(), false);
    }
    let renamed = head
        .split("\r\n")
        .map(|line| match is_protocol_header(line) {
            Some((name, value)) => {
                let protocols: Vec<&str> = value
                    .split(',')
                    .map(|p| if p.trim() == CLASSIC { SDK } else { p.trim() })
                    .collect();
                format!("{name}: {}", protocols.join(", "))
            }
            None => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n");
    (renamed, true)
}

/// The server's answer with the subprotocol it chose named as the client
/// offered it.
pub fn rename_answer(head: &str) -> String {
    head.split("\r\n")
        .map(|line| match is_protocol_header(line) {
            Some((name, value)) if value.trim() == SDK => format!("{name}: {CLASSIC}"),
            _ => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLASSIC_ASK: &str =
        "GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
        Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
        Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n\r\n";

    #[test]
    fn a_classic_client_s_protocol_is_renamed_both_ways() {
        let (asked, renamed) = rename_request(CLASSIC_ASK);
        assert!(renamed);
        assert!(
            asked.contains("\r\nSec-WebSocket-Protocol: foxglove.sdk.v1\r\n"),
            "{asked}"
        );
        assert!(asked.ends_with("\r\n\r\n") && asked.contains("Sec-WebSocket-Key: dGhl"));
        let answer = "HTTP/1.1 101 Switching Protocols\r\nupgrade: websocket\r\n\
                      sec-websocket-protocol: foxglove.sdk.v1\r\n\r\n";
        assert_eq!(
            rename_answer(answer),
            "HTTP/1.1 101 Switching Protocols\r\nupgrade: websocket\r\n\
             sec-websocket-protocol: foxglove.websocket.v1\r\n\r\n"
        );
    }

    #[test]
    fn a_client_of_the_sdk_s_protocol_passes_unchanged() {
        let both = CLASSIC_ASK.replace(
            "foxglove.websocket.v1",
            "foxglove.sdk.v1, foxglove.websocket.v1",
        );
        assert_eq!(rename_request(&both), (both.clone(), false));
        let none = CLASSIC_ASK.replace("Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n", "");
        assert_eq!(rename_request(&none), (none.clone(), false));
        // Several headers, one a list, the name in any case.
        let split = CLASSIC_ASK.replace(
            "Sec-WebSocket-Protocol: foxglove.websocket.v1",
            "sec-websocket-protocol: other\r\nSEC-WEBSOCKET-PROTOCOL: x, foxglove.websocket.v1",
        );
        let (asked, renamed) = rename_request(&split);
        assert!(
            renamed && asked.contains("SEC-WEBSOCKET-PROTOCOL: x, foxglove.sdk.v1"),
            "{asked}"
        );
    }
}
