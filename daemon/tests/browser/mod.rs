//! A small Chrome DevTools Protocol client that drives headless Chromium for the integration tests.
//!
//! The view is a live page fed by a stream, so `--virtual-time-budget` (which fast-forwards a page
//! and then dumps it) does not suit it; the tests instead launch a real browser, open the page over
//! CDP and poll it with JavaScript while it runs. Everything goes over one WebSocket to the browser
//! endpoint, with flattened sessions (one per page), in a blocking single-threaded loop: events are
//! buffered while a caller waits for its reply. Host names other than 127.0.0.1 do not resolve, and
//! every request a page makes is recorded, so a test can check the page stayed on loopback.
#![allow(dead_code)]

use serde_json::{Value, json};
use std::collections::{HashMap, VecDeque};
use std::io::{BufRead, BufReader, ErrorKind};
use std::net::TcpStream;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant, SystemTime};
use tungstenite::{Message, WebSocket};

/// How long a CDP reply, the browser's start or a page load may take.
const TIMEOUT: Duration = Duration::from_secs(20);

/// Chromium's flags, less the profile, window size and first page.
const FLAGS: &[&str] = &[
    "--headless",
    "--no-sandbox",
    "--disable-dev-shm-usage",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--ignore-gpu-blocklist",
    "--autoplay-policy=no-user-gesture-required",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
    "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1",
    "--remote-debugging-port=0",
];

/// The Chromium to drive: `DANCED_CHROMIUM` if set, else the first one installed.
pub fn chromium_path() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("DANCED_CHROMIUM") {
        return Some(path.into());
    }
    let known = ["chromium-headless-shell", "chromium", "chromium-browser"];
    known
        .iter()
        .map(|name| PathBuf::from("/usr/bin").join(name))
        .find(|p| p.exists())
}

/// Whether a Chromium is there to drive; otherwise the test skips (a `SKIP` line, or a failure
/// under `DANCED_REQUIRE_ALL`; see `testkit`).
#[track_caller]
pub fn require_chromium() -> bool {
    if chromium_path().is_some() {
        return true;
    }
    testkit::skip(
        "no Chromium in /usr/bin (apt-get install chromium-headless-shell, or set DANCED_CHROMIUM)",
    );
    false
}

/// The last lines chromium wrote to stderr, for error messages.
type Log = Arc<Mutex<VecDeque<String>>>;

fn tail(log: &Log) -> String {
    let lines: Vec<String> = log.lock().unwrap().iter().cloned().collect();
    format!("chromium's stderr ends:\n{}", lines.join("\n"))
}

/// The connection to the browser endpoint: replies by id, and every event so far.
struct Conn {
    ws: WebSocket<TcpStream>,
    next_id: u64,
    replies: HashMap<u64, Value>,
    events: Vec<Value>,
    stderr: Log,
}

impl Conn {
    fn fail(&self, what: String) -> String {
        format!("{what}\n{}", tail(&self.stderr))
    }

    /// Reads at most one message, waiting up to `timeout`; true if one came.
    fn read(&mut self, timeout: Duration) -> Result<bool, String> {
        let timeout = Some(timeout.max(Duration::from_millis(1)));
        self.ws
            .get_ref()
            .set_read_timeout(timeout)
            .map_err(|e| e.to_string())?;
        let text = match self.ws.read() {
            Ok(Message::Text(text)) => text,
            Ok(_) => return Ok(true),
            Err(tungstenite::Error::Io(e))
                if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) =>
            {
                return Ok(false);
            }
            Err(e) => return Err(self.fail(format!("CDP connection: {e}"))),
        };
        let msg: Value = serde_json::from_str(text.as_str()).map_err(|e| format!("CDP: {e}"))?;
        match msg["id"].as_u64() {
            Some(id) => drop(self.replies.insert(id, msg)),
            None => self.events.push(msg),
        }
        Ok(true)
    }

    /// Reads messages until `done` holds, for at most `TIMEOUT`.
    fn wait(&mut self, what: &str, done: impl Fn(&Conn) -> bool) -> Result<(), String> {
        let deadline = Instant::now() + TIMEOUT;
        while !done(self) {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.fail(format!("{what}: nothing within {TIMEOUT:?}")));
            }
            self.read(left.min(Duration::from_millis(100)))?;
        }
        Ok(())
    }

    /// Takes in whatever messages have already arrived.
    fn drain(&mut self) -> Result<(), String> {
        while self.read(Duration::from_millis(1))? {}
        Ok(())
    }

    /// Sends a command (to a page's session, or to the browser) and waits for its result.
    fn call(
        &mut self,
        session: Option<&str>,
        method: &str,
        params: Value,
    ) -> Result<Value, String> {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({"id": id, "method": method, "params": params});
        if let Some(session) = session {
            msg["sessionId"] = session.into();
        }
        let sent = self.ws.send(Message::Text(msg.to_string().into()));
        sent.map_err(|e| self.fail(format!("CDP send {method}: {e}")))?;
        self.wait(method, |conn| conn.replies.contains_key(&id))?;
        let reply = self.replies.remove(&id).unwrap();
        match reply.get("error") {
            Some(e) => Err(format!("{method}: {e}")),
            None => Ok(reply["result"].clone()),
        }
    }

    /// The events of `session` so far named `method`.
    fn events<'a>(&'a self, session: &'a str, method: &'a str) -> impl Iterator<Item = &'a Value> {
        let matches = move |e: &&Value| e["sessionId"] == session && e["method"] == method;
        self.events.iter().filter(matches)
    }
}

/// Ends chromium and removes its profile when dropped (also when a launch fails half-way).
///
/// Debian's `/usr/bin/chromium*` are shell scripts that run the real browser as their child, so
/// chromium gets a process group of its own and the whole group is killed.
struct Process {
    child: Child,
    dir: PathBuf,
}

impl Drop for Process {
    fn drop(&mut self) {
        // Give a browser that was asked to close a moment to do so, then kill what is left.
        let deadline = Instant::now() + Duration::from_secs(2);
        while self.child.try_wait().is_ok_and(|s| s.is_none()) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        // SAFETY: kill(2) on our own child's process group; nothing is dereferenced.
        unsafe { libc::kill(-(self.child.id() as libc::pid_t), libc::SIGKILL) };
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A headless Chromium child process and the one CDP connection to it.
pub struct Browser {
    conn: Arc<Mutex<Conn>>,
    process: Process,
}

impl Browser {
    /// Starts chromium with a fresh profile and a `width` × `height` window, and connects to it.
    pub fn launch(width: u32, height: u32) -> Result<Browser, String> {
        let exe = chromium_path().ok_or("no chromium found (set DANCED_CHROMIUM)")?;
        let nanos = SystemTime::UNIX_EPOCH.elapsed().unwrap().as_nanos();
        let name = format!("danced-chromium-{}-{nanos}", std::process::id());
        let dir = std::env::temp_dir().join(name);
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let child = Command::new(&exe)
            .args(FLAGS)
            .arg(format!("--user-data-dir={}", dir.display()))
            .arg(format!("--window-size={width},{height}"))
            .arg("about:blank")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .process_group(0)
            .spawn();
        let child = child.map_err(|e| format!("{}: {e}", exe.display()))?;
        let mut process = Process { child, dir };

        // Read stderr for as long as chromium runs, so that it never blocks on a full pipe.
        let mut stderr = BufReader::new(process.child.stderr.take().unwrap());
        let log = Log::default();
        let (url_tx, url_rx) = mpsc::channel();
        let thread_log = log.clone();
        std::thread::spawn(move || {
            let mut line = Vec::new();
            while stderr.read_until(b'\n', &mut line).is_ok_and(|n| n > 0) {
                let text = String::from_utf8_lossy(&line).trim_end().to_string();
                if let Some((_, url)) = text.split_once("DevTools listening on ") {
                    let _ = url_tx.send(url.trim().to_string());
                }
                let mut log = thread_log.lock().unwrap();
                if log.len() == 50 {
                    log.pop_front();
                }
                log.push_back(text);
                line.clear();
            }
        });

        let url = match url_rx.recv_timeout(TIMEOUT) {
            Ok(url) => url,
            Err(mpsc::RecvTimeoutError::Timeout) => {
                let log = tail(&log);
                return Err(format!(
                    "chromium printed no DevTools URL in {TIMEOUT:?}\n{log}"
                ));
            }
            Err(mpsc::RecvTimeoutError::Disconnected) => {
                let status = process
                    .child
                    .wait()
                    .map_or(String::new(), |s| s.to_string());
                let log = tail(&log);
                return Err(format!(
                    "chromium exited ({status}) before it listened\n{log}"
                ));
            }
        };
        let addr = url.strip_prefix("ws://").and_then(|s| s.split('/').next());
        let addr = addr.ok_or_else(|| format!("odd DevTools URL {url}"))?;
        let stream = TcpStream::connect(addr).map_err(|e| format!("{addr}: {e}"))?;
        stream.set_nodelay(true).map_err(|e| e.to_string())?;
        let (ws, _) = tungstenite::client::client(url.as_str(), stream)
            .map_err(|e| format!("WebSocket handshake with {url}: {e}"))?;
        let conn = Conn {
            ws,
            next_id: 0,
            replies: HashMap::new(),
            events: Vec::new(),
            stderr: log,
        };
        let conn = Arc::new(Mutex::new(conn));
        Ok(Browser { conn, process })
    }

    /// Opens a new tab, enables the domains the tests read, and loads `url` in it.
    pub fn open(&self, url: &str) -> Result<Page, String> {
        let mut conn = self.conn.lock().unwrap();
        let target = conn.call(None, "Target.createTarget", json!({"url": "about:blank"}))?;
        let target = field(&target, "targetId")?;
        let params = json!({"targetId": target, "flatten": true});
        let session = conn.call(None, "Target.attachToTarget", params)?;
        let session = field(&session, "sessionId")?;
        for domain in ["Page", "Runtime", "Network"] {
            conn.call(Some(&session), &format!("{domain}.enable"), json!({}))?;
        }
        let loads = |conn: &Conn| conn.events(&session, "Page.loadEventFired").count();
        let before = loads(&conn);
        let nav = conn.call(Some(&session), "Page.navigate", json!({"url": url}))?;
        if let Some(error) = nav["errorText"].as_str() {
            return Err(format!("navigating to {url}: {error}"));
        }
        conn.wait(&format!("loading {url}"), |conn| loads(conn) > before)?;
        Ok(Page {
            conn: self.conn.clone(),
            session,
            target,
        })
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        if let Ok(mut conn) = self.conn.lock() {
            let _ = conn.call(None, "Browser.close", json!({}));
        }
    }
}

/// A tab attached through its own CDP session; closed when dropped.
pub struct Page {
    conn: Arc<Mutex<Conn>>,
    session: String,
    target: String,
}

impl Page {
    fn call(&self, method: &str, params: Value) -> Result<Value, String> {
        let mut conn = self.conn.lock().unwrap();
        conn.call(Some(&self.session), method, params)
    }

    /// Evaluates `js`: Ok(Ok(value)), or Ok(Err(text)) if it threw, or Err if CDP failed.
    fn try_eval(&self, js: &str) -> Result<Result<Value, String>, String> {
        let params = json!({"expression": js, "awaitPromise": true, "returnByValue": true});
        let reply = self.call("Runtime.evaluate", params)?;
        Ok(match reply.get("exceptionDetails") {
            Some(ex) => Err(format!("`{js}` threw: {}", exception_text(ex))),
            None => Ok(reply["result"].get("value").cloned().unwrap_or(Value::Null)),
        })
    }

    /// Evaluates `js` in the page (awaiting a promise) and returns its value as JSON.
    pub fn eval(&self, js: &str) -> Result<Value, String> {
        self.try_eval(js)?
    }

    /// Polls `js_condition` until it is truthy and returns its value (throwing counts as false).
    pub fn wait_for(&self, js_condition: &str, timeout: Duration) -> Result<Value, String> {
        let deadline = Instant::now() + timeout;
        loop {
            let last = match self.try_eval(js_condition)? {
                Ok(value) if truthy(&value) => return Ok(value),
                Ok(value) => value.to_string(),
                Err(thrown) => thrown,
            };
            if Instant::now() >= deadline {
                let console = self.console().join("\n");
                let what = format!("`{js_condition}` not true within {timeout:?}");
                return Err(format!("{what}; last: {last}\nconsole:\n{console}"));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The page's console messages and uncaught exceptions so far, as "level: text".
    pub fn console(&self) -> Vec<String> {
        let mut conn = self.conn.lock().unwrap();
        let _ = conn.drain();
        let mine = conn
            .events
            .iter()
            .filter(|e| e["sessionId"] == *self.session);
        let line = |event: &Value| {
            let params = &event["params"];
            match event["method"].as_str()? {
                "Runtime.consoleAPICalled" => {
                    let args = params["args"].as_array()?.iter().map(remote_text);
                    let level = params["type"].as_str().unwrap_or("log");
                    Some(format!("{level}: {}", args.collect::<Vec<_>>().join(" ")))
                }
                "Runtime.exceptionThrown" => {
                    let text = exception_text(&params["exceptionDetails"]);
                    Some(format!("exception: {text}"))
                }
                _ => None,
            }
        };
        mine.filter_map(line).collect()
    }

    /// The URLs of every request the page has made so far.
    pub fn requests(&self) -> Vec<String> {
        let mut conn = self.conn.lock().unwrap();
        let _ = conn.drain();
        let sent = conn.events(&self.session, "Network.requestWillBeSent");
        let url = |e: &Value| e["params"]["request"]["url"].as_str().map(String::from);
        sent.filter_map(url).collect()
    }

    /// A PNG screenshot of the page's viewport.
    pub fn screenshot_png(&self) -> Result<Vec<u8>, String> {
        let shot = self.call("Page.captureScreenshot", json!({"format": "png"}))?;
        base64_decode(shot["data"].as_str().ok_or("screenshot without data")?)
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        if let Ok(mut conn) = self.conn.lock() {
            let _ = conn.call(None, "Target.closeTarget", json!({"targetId": self.target}));
        }
    }
}

/// The string `name` of a CDP result.
fn field(result: &Value, name: &str) -> Result<String, String> {
    let value = result[name]
        .as_str()
        .ok_or_else(|| format!("no {name} in {result}"));
    value.map(String::from)
}

/// JavaScript truthiness of a JSON value.
fn truthy(value: &Value) -> bool {
    match value {
        Value::Null => false,
        Value::Bool(b) => *b,
        Value::Number(n) => n.as_f64().is_some_and(|n| n != 0.0),
        Value::String(s) => !s.is_empty(),
        Value::Array(_) | Value::Object(_) => true,
    }
}

/// The message of a CDP `exceptionDetails`.
fn exception_text(ex: &Value) -> &str {
    let description = ex["exception"]["description"].as_str();
    description
        .or(ex["text"].as_str())
        .unwrap_or("an exception")
}

/// A console argument (a CDP `RemoteObject`) as text.
fn remote_text(arg: &Value) -> String {
    match (&arg["value"], arg["description"].as_str()) {
        (Value::String(s), _) => s.clone(),
        (Value::Null, Some(description)) => description.to_string(),
        (Value::Null, None) => arg["type"].as_str().unwrap_or("null").to_string(),
        (value, _) => value.to_string(),
    }
}

/// Decodes standard base64 (padding and whitespace ignored).
fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let mut out = Vec::with_capacity(text.len() / 4 * 3);
    let (mut acc, mut bits) = (0u32, 0);
    for c in text
        .bytes()
        .filter(|c| *c != b'=' && !c.is_ascii_whitespace())
    {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return Err(format!("not base64: byte {c:#04x}")),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
        }
    }
    Ok(out)
}
