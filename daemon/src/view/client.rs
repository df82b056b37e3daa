//! One browser connected to the view: a non-blocking WebSocket that skips frames while its
//! socket is full and is dropped when it stays behind, so one slow tab cannot slow the others.

use std::io;
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use tungstenite::{Message, WebSocket};

/// How long a client may stay unable to take data before it is disconnected.
pub const MAX_BEHIND: Duration = Duration::from_secs(2);
/// Bytes tungstenite may hold for a client whose socket is full (a few frames; beyond it the
/// client is behind and frames are skipped, never queued).
pub const MAX_BUFFERED_BYTES: usize = 256 * 1024;

/// Kernel send buffer per client: about half a second of frames. Left to autotuning, Linux lets
/// it grow to megabytes, which a stalled tab (a background one, say) would fill with a minute
/// of stale frames to play back late; kept small, it is found behind at once and skips instead.
pub const SEND_BUFFER_BYTES: i32 = 32 * 1024;

/// What became of a write or a read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClientState {
    /// Up to date.
    Ok,
    /// Its socket is full; newer frames are skipped until it drains.
    Behind,
    /// Gone (closed, failed, or behind for longer than [`MAX_BEHIND`]).
    Gone,
}

/// A connected browser.
pub struct ViewClient {
    ws: WebSocket<TcpStream>,
    /// Its address (for logs).
    pub peer: SocketAddr,
    behind_since: Option<Instant>,
}

impl ViewClient {
    /// Wraps an accepted WebSocket, making its socket non-blocking.
    pub fn new(ws: WebSocket<TcpStream>) -> io::Result<Self> {
        let stream = ws.get_ref();
        let peer = stream.peer_addr()?;
        stream.set_nonblocking(true)?;
        // Frames are small and latency matters more than packet count.
        stream.set_nodelay(true)?;
        limit_send_buffer(stream);
        Ok(Self {
            ws,
            peer,
            behind_since: None,
        })
    }

    /// Whether it is still taking the earlier frames.
    pub fn is_behind(&self) -> bool {
        self.behind_since.is_some()
    }

    /// Queues `message` and pushes what it can to the socket.
    pub fn send(&mut self, message: Message, now: Instant) -> ClientState {
        match self.ws.write(message) {
            Ok(()) => self.flush(now),
            Err(tungstenite::Error::WriteBufferFull(_)) => self.mark_behind(now),
            Err(tungstenite::Error::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => {
                self.mark_behind(now)
            }
            Err(_) => ClientState::Gone,
        }
    }

    /// Pushes buffered bytes to the socket.
    pub fn flush(&mut self, now: Instant) -> ClientState {
        match self.ws.flush() {
            Ok(()) => {
                self.behind_since = None;
                ClientState::Ok
            }
            Err(tungstenite::Error::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => {
                self.mark_behind(now)
            }
            Err(_) => ClientState::Gone,
        }
    }

    fn mark_behind(&mut self, now: Instant) -> ClientState {
        let since = *self.behind_since.get_or_insert(now);
        if now.duration_since(since) > MAX_BEHIND {
            ClientState::Gone
        } else {
            ClientState::Behind
        }
    }

    /// Hands every binary message that has arrived to `on_binary`; `Gone` once it closed.
    pub fn read(&mut self, mut on_binary: impl FnMut(&[u8])) -> ClientState {
        loop {
            match self.ws.read() {
                Ok(Message::Binary(b)) => on_binary(&b),
                // Text, pings (answered by tungstenite on the next write) and pongs.
                Ok(Message::Close(_)) => return ClientState::Gone,
                Ok(_) => {}
                Err(tungstenite::Error::Io(e)) if e.kind() == io::ErrorKind::WouldBlock => {
                    return ClientState::Ok;
                }
                Err(_) => return ClientState::Gone,
            }
        }
    }
}

fn limit_send_buffer(stream: &TcpStream) {
    use std::os::fd::AsRawFd;
    let size = SEND_BUFFER_BYTES;
    // SAFETY: setsockopt reads one c_int from a live local for a socket this stream owns.
    let rc = unsafe {
        libc::setsockopt(
            stream.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_SNDBUF,
            (&size as *const i32).cast(),
            std::mem::size_of::<i32>() as libc::socklen_t,
        )
    };
    if rc != 0 {
        tracing::debug!(
            "view: SO_SNDBUF not set: {}",
            std::io::Error::last_os_error()
        );
    }
}

/// tungstenite's settings for view clients: small buffers, a cap on what a stalled client holds,
/// and small incoming messages (the page only sends control messages).
pub fn websocket_config() -> tungstenite::protocol::WebSocketConfig {
    tungstenite::protocol::WebSocketConfig::default()
        .write_buffer_size(0)
        .max_write_buffer_size(MAX_BUFFERED_BYTES)
        .max_message_size(Some(64 * 1024))
        .max_frame_size(Some(64 * 1024))
}
