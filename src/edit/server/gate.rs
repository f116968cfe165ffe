//! Who may ask the editor's server, and how it answers: the session's token, the `Host` and
//! `Origin` a request must carry ([`Gate`]), the request's head read within its time and size,
//! and the answers with their security headers (the module docs of [`super`]).

use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Instant;

use super::{HEAD_BYTES, HEAD_TIME};
use crate::error::{Error, Result};

/// 128 random bits as hex, from the system's generator.
pub(super) fn token() -> Result<String> {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(|e| Error::solver(format!("no random token: /dev/urandom: {e}")))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Whether two secrets are equal, in a time that depends on their lengths alone (not on where
/// they first differ).
pub(super) fn same_secret(a: &[u8], b: &[u8]) -> bool {
    let differ = a
        .iter()
        .zip(b)
        .fold(0u8, |acc, (x, y)| acc | std::hint::black_box(x ^ y));
    a.len() == b.len() && differ == 0
}

/// What a request must carry.
pub(super) struct Gate {
    pub(super) token: String,
    pub(super) port: u16,
}

impl Gate {
    /// Whether the request's token, `Host` and `Origin` are this server's.
    pub(super) fn admits(&self, query: &str, headers: &[httparse::Header<'_>]) -> bool {
        let token_ok = query
            .split('&')
            .filter_map(|kv| kv.split_once('='))
            .filter(|(k, _)| *k == "t")
            .fold(false, |ok, (_, v)| {
                same_secret(v.as_bytes(), self.token.as_bytes()) | ok
            });
        let host_ok = header(headers, "host").is_some_and(|h| self.hosts().contains(&h));
        let origin_ok = header(headers, "origin")
            .is_none_or(|o| self.hosts().iter().any(|h| o == format!("http://{h}")));
        token_ok && host_ok && origin_ok
    }

    /// The names of this server as a `Host` header gives them.
    fn hosts(&self) -> [String; 2] {
        [
            format!("127.0.0.1:{}", self.port),
            format!("localhost:{}", self.port),
        ]
    }
}

/// The value of the header `name`, if the request has it.
pub(super) fn header(headers: &[httparse::Header<'_>], name: &str) -> Option<String> {
    headers
        .iter()
        .find(|h| h.name.eq_ignore_ascii_case(name))
        .map(|h| String::from_utf8_lossy(h.value).into_owned())
}

/// The request's head, read within [`HEAD_TIME`], and the bytes read after it; `None` when it
/// is larger than [`HEAD_BYTES`] or slower.
pub(super) fn read_head(stream: &mut TcpStream) -> std::io::Result<Option<(Vec<u8>, Vec<u8>)>> {
    let deadline = Instant::now() + HEAD_TIME;
    let mut buf = vec![0u8; HEAD_BYTES];
    let mut len = 0;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() || len == buf.len() {
            return Ok(None);
        }
        stream.set_read_timeout(Some(left))?;
        let n = match stream.read(&mut buf[len..]) {
            Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => n,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) =>
            {
                return Ok(None);
            }
            Err(e) => return Err(e),
        };
        let from = len.saturating_sub(3);
        len += n;
        if let Some(at) = buf[from..len].windows(4).position(|w| w == b"\r\n\r\n") {
            let end = from + at + 4;
            let rest = buf[end..len].to_vec();
            buf.truncate(end);
            return Ok(Some((buf, rest)));
        }
    }
}

/// The Content-Security-Policy of the server on `port`: its own script and styles only, no
/// inline code, connections only to itself, never framed.
pub(super) fn policy(port: u16) -> String {
    format!(
        "default-src 'none'; script-src 'self'; style-src 'self'; \
         connect-src 'self' ws://127.0.0.1:{port} ws://localhost:{port}; \
         base-uri 'none'; form-action 'none'; frame-ancestors 'none'"
    )
}

pub(super) fn respond(
    stream: &mut TcpStream,
    status: u16,
    kind: &str,
    body: &[u8],
    port: u16,
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        204 => "No Content",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        503 => "Service Unavailable",
        _ => "Request Header Fields Too Large",
    };
    // A 204 has no body, and says nothing of one.
    let body_head = match status {
        204 => String::new(),
        _ => format!("Content-Type: {kind}\r\nContent-Length: {}\r\n", body.len()),
    };
    write!(
        stream,
        "HTTP/1.1 {status} {reason}\r\n{body_head}\
         Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\n\
         Referrer-Policy: no-referrer\r\nContent-Security-Policy: {}\r\n\
         Connection: close\r\n\r\n",
        policy(port)
    )?;
    stream.write_all(body)?;
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_are_equal_only_when_every_byte_is() {
        let token = b"0123456789abcdef0123456789abcdef";
        assert!(same_secret(token, token));
        let mut last = *token;
        last[31] = b'0';
        assert!(!same_secret(&last, token));
        let mut first = *token;
        first[0] = b'1';
        assert!(!same_secret(&first, token));
        assert!(!same_secret(&token[..31], token));
        assert!(!same_secret(b"", token));
        assert!(!same_secret(token, b""));
    }
}
