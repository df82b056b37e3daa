//! The view's server: an acceptor thread answers HTTP (each request on a short-lived thread, so
//! a 250 KB script never delays a frame) and upgrades `GET /ws`; one view thread forwards the
//! newest frame (as the VMC bundle a VMC receiver gets), the beat and other analysis events (as
//! native OSC) and a status line to every browser, and feeds what the page sends into the same
//! control path as OSC and MIDI.

use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use crossbeam_channel::{Receiver, Sender};
use protocols::{ControlParser, NativeEncoder, PacketPool, VmcEncoder};
use tungstenite::{Message, WebSocket};

use super::assets::Assets;
use super::client::{ClientState, ViewClient, websocket_config};
use super::counters::{ViewCounters, ViewReport};
use super::http::{self, RequestHead};
use super::hud::{self, ViewHello, ViewStatus};
use super::sink::{VIEW_EVENT_QUEUE, ViewSink};
use crate::frame::FrameBuilder;
use crate::live::control_queue::ControlSender;
use crate::live::stats::Stats;
use crate::live::wire::{AnalysisEvent, BodyFrame};

/// The address the view listens on unless told otherwise (this machine only).
pub const DEFAULT_VIEW_ADDR: &str = "127.0.0.1:8080";
/// Most browsers connected at once.
pub const MAX_CLIENTS: usize = 8;
/// Shortest spacing of frames to a browser (a display shows at most 60 a second; the 10 %
/// slack keeps a 60 Hz sender's jitter from skipping frames).
pub const MIN_FRAME_SPACING: Duration = Duration::from_micros(15_000);
/// How often the status message goes out.
pub const STATUS_PERIOD: Duration = Duration::from_millis(100);
/// How long an HTTP client may take to send its request or read the answer.
const HTTP_TIMEOUT: Duration = Duration::from_secs(10);

/// What the live run gives the view: its counters to show and a control input of its own.
pub struct LiveFeed {
    /// The run's counters (the HUD reads them).
    pub stats: Arc<Stats>,
    /// The page's controls enter the control path here (validated and counted like OSC's).
    pub controls: ControlSender,
}

/// A running view server.
pub struct ViewServer {
    addr: SocketAddr,
    counters: Arc<ViewCounters>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
}

impl ViewServer {
    /// Listens on `addr` and serves `assets`; with a `feed`, it also returns the sink the
    /// sender thread hands frames to. Everything stops when `stop` is set.
    pub fn start(
        addr: &str,
        assets: Assets,
        hello: ViewHello,
        feed: Option<LiveFeed>,
        stop: Arc<AtomicBool>,
    ) -> Result<(Self, Option<ViewSink>)> {
        let addr: SocketAddr = addr
            .parse()
            .with_context(|| format!("view address {addr:?} is not host:port"))?;
        let listener =
            TcpListener::bind(addr).with_context(|| format!("serving the view on {addr}"))?;
        let addr = listener.local_addr()?;
        if !addr.ip().is_loopback() {
            tracing::warn!(
                "the view listens on {addr}, beyond this machine: anyone on the network can \
                 watch and steer the dancer"
            );
        }
        listener.set_nonblocking(true)?;
        let counters = Arc::new(ViewCounters::default());
        let (clients_tx, clients_rx) = crossbeam_channel::bounded(MAX_CLIENTS);
        let open = Arc::new(AtomicUsize::new(0));
        let poses = hello.poses.clone();
        let hello = hud::message("hello", &hello);
        let live = feed.is_some();
        // Three full frames up front: the sender's copies never allocate.
        let mut builder = FrameBuilder::new();
        let first = builder
            .build(0, 0.0, &model::rig::Pose::rest(), 0.0)
            .clone();
        let (frames_in, frames_out) = triple_buffer::triple_buffer(&first);
        let (events_in, events_out) = rtrb::RingBuffer::new(VIEW_EVENT_QUEUE);
        let view = {
            let mut state = ViewThread {
                frames: frames_out,
                events: events_out,
                clients_rx,
                clients: Vec::with_capacity(MAX_CLIENTS),
                open: open.clone(),
                counters: counters.clone(),
                feed,
                hello,
                parser: ControlParser::default(),
                poses,
                stop: stop.clone(),
            };
            std::thread::Builder::new()
                .name("danced-view".into())
                .spawn(move || state.run())
                .context("starting the view thread")?
        };
        let sink = live.then(|| {
            ViewSink::new(
                frames_in,
                events_in,
                view.thread().clone(),
                counters.clone(),
            )
        });
        let acceptor = {
            let (counters, stop, assets) = (counters.clone(), stop.clone(), Arc::new(assets));
            std::thread::Builder::new()
                .name("danced-view-http".into())
                .spawn(move || accept_loop(listener, assets, clients_tx, open, counters, stop))
                .context("starting the view's HTTP thread")?
        };
        Ok((
            Self {
                addr,
                counters,
                stop,
                threads: vec![view, acceptor],
            },
            sink,
        ))
    }

    /// Where the page is.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Its counters so far.
    pub fn report(&self) -> ViewReport {
        self.counters.report()
    }

    /// Stops the server (sets the shared stop flag) and waits for its threads.
    pub fn stop(self) -> ViewReport {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads {
            t.thread().unpark();
            let _ = t.join();
        }
        self.counters.report()
    }
}

fn accept_loop(
    listener: TcpListener,
    assets: Arc<Assets>,
    clients: Sender<WebSocket<TcpStream>>,
    open: Arc<AtomicUsize>,
    counters: Arc<ViewCounters>,
    stop: Arc<AtomicBool>,
) {
    while !stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                let (assets, clients, open, c) = (
                    assets.clone(),
                    clients.clone(),
                    open.clone(),
                    counters.clone(),
                );
                let spawned = std::thread::Builder::new()
                    .name("danced-view-req".into())
                    .spawn(move || handle(stream, &assets, &clients, &open, &c));
                if spawned.is_err() {
                    counters.http_errors.fetch_add(1, Ordering::Relaxed);
                }
            }
            // Non-blocking: a 20 ms nap bounds how long a stop or a new tab waits.
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// One connection: a file, or the WebSocket handed to the view thread.
fn handle(
    mut stream: TcpStream,
    assets: &Assets,
    clients: &Sender<WebSocket<TcpStream>>,
    open: &AtomicUsize,
    counters: &ViewCounters,
) {
    // Accepted sockets may inherit non-blocking mode from the listener on some systems.
    let _ = stream.set_nonblocking(false);
    let _ = stream.set_read_timeout(Some(HTTP_TIMEOUT));
    let _ = stream.set_write_timeout(Some(HTTP_TIMEOUT));
    let head = match http::peek_head(&stream, HTTP_TIMEOUT) {
        Ok(h) => h,
        Err(e) => {
            tracing::debug!("view: {e}");
            counters.http_errors.fetch_add(1, Ordering::Relaxed);
            return;
        }
    };
    if head.path == "/ws" && head.websocket {
        upgrade(stream, &head, clients, open, counters);
        return;
    }
    let served = match (head.method.as_str(), assets.get(&head.path)) {
        ("GET" | "HEAD", Some(a)) => http::respond(
            &mut stream,
            &head,
            "200 OK",
            a.content_type,
            a.gzip,
            &a.body,
        )
        .map(|_| true),
        ("GET" | "HEAD", None) => http::respond(
            &mut stream,
            &head,
            "404 Not Found",
            "text/plain",
            false,
            b"not found\n",
        )
        .map(|_| false),
        _ => http::respond(
            &mut stream,
            &head,
            "405 Method Not Allowed",
            "text/plain",
            false,
            b"GET only\n",
        )
        .map(|_| false),
    };
    let counter = match served {
        Ok(true) => &counters.http_served,
        _ => &counters.http_errors,
    };
    counter.fetch_add(1, Ordering::Relaxed);
}

fn upgrade(
    mut stream: TcpStream,
    head: &RequestHead,
    clients: &Sender<WebSocket<TcpStream>>,
    open: &AtomicUsize,
    counters: &ViewCounters,
) {
    let refuse = |stream: &mut TcpStream, status: &str, why: &[u8]| {
        counters.clients_refused.fetch_add(1, Ordering::Relaxed);
        let _ = http::respond(stream, head, status, "text/plain", false, why);
    };
    if !http::same_origin(head.origin.as_deref(), head.host.as_deref()) {
        tracing::warn!(
            "view: refused a WebSocket from {:?} (only the view's own page may steer the dancer)",
            head.origin
        );
        refuse(&mut stream, "403 Forbidden", b"another site's page\n");
        return;
    }
    if open.fetch_add(1, Ordering::AcqRel) >= MAX_CLIENTS {
        open.fetch_sub(1, Ordering::AcqRel);
        refuse(
            &mut stream,
            "503 Service Unavailable",
            b"too many viewers\n",
        );
        return;
    }
    let ws = match tungstenite::accept_with_config(stream, Some(websocket_config())) {
        Ok(ws) => ws,
        Err(e) => {
            tracing::debug!("view: WebSocket handshake failed: {e}");
            open.fetch_sub(1, Ordering::AcqRel);
            counters.clients_refused.fetch_add(1, Ordering::Relaxed);
            return;
        }
    };
    if clients.try_send(ws).is_err() {
        open.fetch_sub(1, Ordering::AcqRel);
        counters.clients_refused.fetch_add(1, Ordering::Relaxed);
    }
}

/// The view thread's state.
struct ViewThread {
    frames: triple_buffer::Output<BodyFrame>,
    events: rtrb::Consumer<AnalysisEvent>,
    clients_rx: Receiver<WebSocket<TcpStream>>,
    clients: Vec<ViewClient>,
    open: Arc<AtomicUsize>,
    counters: Arc<ViewCounters>,
    feed: Option<LiveFeed>,
    hello: String,
    parser: ControlParser,
    poses: Vec<String>,
    stop: Arc<AtomicBool>,
}

impl ViewThread {
    fn run(&mut self) {
        let mut vmc = VmcEncoder::new(false);
        let mut native = NativeEncoder::default();
        let mut pool = PacketPool::new();
        let mut controls = Vec::with_capacity(16);
        let mut last_frame: Option<Instant> = None;
        let mut next_status = Instant::now();
        while !self.stop.load(Ordering::Relaxed) {
            let now = Instant::now();
            while let Ok(ws) = self.clients_rx.try_recv() {
                self.admit(ws, now);
            }
            let frame_due = last_frame.is_none_or(|t| now.duration_since(t) >= MIN_FRAME_SPACING);
            if frame_due && self.frames.updated() {
                let frame = self.frames.read();
                last_frame = Some(now);
                if !self.clients.is_empty() {
                    vmc.write_frame(frame, &mut pool);
                    let packets: Vec<Message> = pool
                        .packets()
                        .iter()
                        .map(|p| Message::binary(p.clone()))
                        .collect();
                    self.broadcast(&packets, true, now);
                }
            }
            while let Ok(e) = self.events.pop() {
                // Taken either way (the queue must not fill), encoded only for someone.
                if !self.clients.is_empty() {
                    let bytes = native.encode_event(&e).to_vec();
                    self.broadcast(&[Message::binary(bytes)], false, now);
                }
            }
            if now >= next_status {
                if let Some(feed) = self.feed.as_ref().filter(|_| !self.clients.is_empty()) {
                    let status = ViewStatus::read(&feed.stats, &self.poses);
                    let text = hud::message("status", &status);
                    self.broadcast(&[Message::text(text)], false, now);
                }
                next_status = now + STATUS_PERIOD;
            }
            self.read_controls(&mut controls, now);
            self.counters
                .thread_cpu_us
                .store(thread_cpu_us(), Ordering::Relaxed);
            // Woken by the sink at each frame; otherwise the status (or a behind client's
            // flush, or the frame spacing) is the next thing due.
            let mut wait = next_status.saturating_duration_since(Instant::now());
            if self.clients.iter().any(ViewClient::is_behind) || !self.clients_rx.is_empty() {
                wait = wait.min(Duration::from_millis(5));
            }
            if let Some(t) = last_frame
                && self.frames.updated()
            {
                wait = wait.min((t + MIN_FRAME_SPACING).saturating_duration_since(Instant::now()));
            }
            std::thread::park_timeout(wait.min(STATUS_PERIOD));
        }
        for c in &mut self.clients {
            let _ = c.send(Message::Close(None), Instant::now());
        }
    }

    fn admit(&mut self, ws: WebSocket<TcpStream>, now: Instant) {
        match ViewClient::new(ws) {
            Ok(mut c) => {
                if c.send(Message::text(self.hello.clone()), now) != ClientState::Gone {
                    tracing::info!("view: {} connected", c.peer);
                    self.counters
                        .clients_accepted
                        .fetch_add(1, Ordering::Relaxed);
                    self.clients.push(c);
                    return;
                }
            }
            Err(e) => tracing::debug!("view: {e}"),
        }
        self.open.fetch_sub(1, Ordering::AcqRel);
    }

    /// Sends `messages` to every client; a frame (`skippable`) is skipped for a client that is
    /// behind, anything else is queued for it.
    fn broadcast(&mut self, messages: &[Message], skippable: bool, now: Instant) {
        let counters = &self.counters;
        let mut gone = Vec::new();
        for (i, c) in self.clients.iter_mut().enumerate() {
            let mut state = c.flush(now);
            if skippable && state == ClientState::Behind {
                counters.frames_skipped.fetch_add(1, Ordering::Relaxed);
                continue;
            }
            for m in messages {
                if state == ClientState::Gone {
                    break;
                }
                state = c.send(m.clone(), now);
            }
            match state {
                ClientState::Gone => gone.push(i),
                _ if skippable => {
                    counters.frames_forwarded.fetch_add(1, Ordering::Relaxed);
                }
                _ => {}
            }
        }
        self.remove(&gone);
    }

    fn read_controls(&mut self, events: &mut Vec<protocols::ControlEvent>, now: Instant) {
        let mut gone = Vec::new();
        for (i, c) in self.clients.iter_mut().enumerate() {
            let parser = &mut self.parser;
            let feed = &mut self.feed;
            let state = c.read(|bytes| {
                events.clear();
                parser.parse(bytes, events);
                if let Some(feed) = feed.as_mut() {
                    for e in events.drain(..) {
                        // Refusals are counted by the control path.
                        let _ = feed.controls.send(e);
                    }
                }
            });
            if state == ClientState::Gone || c.flush(now) == ClientState::Gone {
                gone.push(i);
            }
        }
        self.counters
            .controls_accepted
            .store(self.parser.accepted(), Ordering::Relaxed);
        self.counters
            .controls_ignored
            .store(self.parser.ignored(), Ordering::Relaxed);
        self.remove(&gone);
    }

    fn remove(&mut self, gone: &[usize]) {
        for &i in gone.iter().rev() {
            let c = self.clients.swap_remove(i);
            if c.is_behind() {
                tracing::warn!("view: {} fell behind and was disconnected", c.peer);
                self.counters
                    .clients_dropped_slow
                    .fetch_add(1, Ordering::Relaxed);
            } else {
                tracing::info!("view: {} left", c.peer);
            }
            self.open.fetch_sub(1, Ordering::AcqRel);
        }
    }
}

/// CPU time this thread has used, µs.
fn thread_cpu_us() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec we own.
    let ok = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0;
    if ok {
        ts.tv_sec as u64 * 1_000_000 + ts.tv_nsec as u64 / 1000
    } else {
        0
    }
}
