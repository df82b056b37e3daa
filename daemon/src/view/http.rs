//! Just enough HTTP/1.1 for the view: read one request head, answer with one file or an error,
//! close. WebSocket upgrades are recognised here and handed to tungstenite.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

/// Longest request head accepted (browsers send well under 2 KiB).
pub const MAX_HEAD_BYTES: usize = 8192;

/// What the view needs of a request.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RequestHead {
    /// `GET`, `HEAD`, ...
    pub method: String,
    /// The path without the query.
    pub path: String,
    /// The `Host` header.
    pub host: Option<String>,
    /// The `Origin` header (browsers send it with WebSocket upgrades).
    pub origin: Option<String>,
    /// Whether it asks for a WebSocket upgrade.
    pub websocket: bool,
    /// Bytes of the head, blank line included.
    pub len: usize,
}

/// Why a request could not be read.
#[derive(Debug, thiserror::Error)]
pub enum HttpError {
    /// The connection failed or timed out.
    #[error("reading the request: {0}")]
    Io(#[from] io::Error),
    /// The head is not HTTP or is too long.
    #[error("bad request: {0}")]
    Malformed(String),
}

/// Parses a complete request head (`None` while more bytes are needed).
pub fn parse_head(bytes: &[u8]) -> Result<Option<RequestHead>, HttpError> {
    let mut headers = [httparse::EMPTY_HEADER; 48];
    let mut req = httparse::Request::new(&mut headers);
    let len = match req.parse(bytes) {
        Ok(httparse::Status::Complete(n)) => n,
        Ok(httparse::Status::Partial) if bytes.len() >= MAX_HEAD_BYTES => {
            return Err(HttpError::Malformed("request head too long".into()));
        }
        Ok(httparse::Status::Partial) => return Ok(None),
        Err(e) => return Err(HttpError::Malformed(e.to_string())),
    };
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .and_then(|h| std::str::from_utf8(h.value).ok())
            .map(|v| v.trim().to_string())
    };
    let path = req.path.unwrap_or("/");
    let path = path.split(['?', '#']).next().unwrap_or("/").to_string();
    Ok(Some(RequestHead {
        method: req.method.unwrap_or("").to_string(),
        websocket: header("upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket")),
        host: header("host"),
        origin: header("origin"),
        path,
        len,
    }))
}

/// Reads the request head without consuming it (tungstenite reads it again for an upgrade).
pub fn peek_head(stream: &TcpStream, timeout: Duration) -> Result<RequestHead, HttpError> {
    let deadline = Instant::now() + timeout;
    let mut buf = vec![0u8; MAX_HEAD_BYTES];
    let mut seen = 0;
    loop {
        let n = stream.peek(&mut buf)?;
        if n == 0 {
            return Err(HttpError::Malformed(
                "connection closed before the request".into(),
            ));
        }
        if let Some(head) = parse_head(&buf[..n])? {
            return Ok(head);
        }
        if Instant::now() >= deadline {
            return Err(HttpError::Io(io::ErrorKind::TimedOut.into()));
        }
        if n == seen {
            // peek returns at once while the head is incomplete: wait for more to arrive.
            std::thread::sleep(Duration::from_millis(2));
        }
        seen = n;
    }
}

/// Whether a browser page from `origin` may open the view's WebSocket on `host`: only the
/// view's own page (same host and port), so another site open in the performer's browser
/// cannot steer the dancer. Clients without an `Origin` (not browsers) are let in.
pub fn same_origin(origin: Option<&str>, host: Option<&str>) -> bool {
    let Some(origin) = origin else {
        return true;
    };
    let Some(host) = host else {
        return false;
    };
    origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"))
        .is_some_and(|o| o.eq_ignore_ascii_case(host))
}

/// Consumes the head that was peeked, then writes a complete response and flushes it.
pub fn respond(
    stream: &mut TcpStream,
    head: &RequestHead,
    status: &str,
    content_type: &str,
    gzip: bool,
    body: &[u8],
) -> io::Result<()> {
    let mut sink = vec![0u8; head.len];
    stream.read_exact(&mut sink)?;
    let encoding = if gzip {
        "Content-Encoding: gzip\r\n"
    } else {
        ""
    };
    let header = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\n{encoding}Content-Length: {}\r\nCache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nConnection: close\r\n\r\n",
        body.len()
    );
    stream.write_all(header.as_bytes())?;
    if head.method != "HEAD" {
        stream.write_all(body)?;
    }
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_websocket_upgrade_and_strips_the_query() {
        let raw = b"GET /ws?x=1 HTTP/1.1\r\nHost: 127.0.0.1:8080\r\nUpgrade: WebSocket\r\nConnection: Upgrade\r\nOrigin: http://127.0.0.1:8080\r\n\r\nrest";
        let h = parse_head(raw).unwrap().unwrap();
        assert_eq!(h.method, "GET");
        assert_eq!(h.path, "/ws");
        assert!(h.websocket);
        assert_eq!(h.len, raw.len() - 4);
        assert!(same_origin(h.origin.as_deref(), h.host.as_deref()));
    }

    #[test]
    fn incomplete_heads_wait_and_garbage_is_refused() {
        assert!(parse_head(b"GET / HTTP/1.1\r\nHost: a").unwrap().is_none());
        assert!(matches!(
            parse_head(b"\x16\x03\x01 binary"),
            Err(HttpError::Malformed(_))
        ));
        let long = [b'a'; MAX_HEAD_BYTES];
        let mut req = b"GET / HTTP/1.1\r\nX: ".to_vec();
        req.extend_from_slice(&long);
        assert!(matches!(parse_head(&req), Err(HttpError::Malformed(_))));
    }

    #[test]
    fn other_sites_may_not_open_the_socket() {
        let host = Some("127.0.0.1:8080");
        assert!(same_origin(None, host));
        assert!(same_origin(Some("http://127.0.0.1:8080"), host));
        assert!(!same_origin(Some("http://evil.example"), host));
        assert!(!same_origin(Some("http://127.0.0.1:8081"), host));
        assert!(!same_origin(Some("null"), host));
        assert!(!same_origin(Some("http://127.0.0.1:8080"), None));
    }
}
