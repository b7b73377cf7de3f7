//! The live page of a watch: one page (HTML, script and style, all in the binary) and a stream
//! of server-sent events, served over plain HTTP/1.1 to the people following the well.
//!
//! - `GET /` the page, `GET /page.js`, `GET /page.css` its parts, `GET /events` the stream
//!   (first the history: every window so far, the latest picture and whether the watch has
//!   ended; then each window as it is given), `GET /state.json` the history at once. Nothing
//!   else: any other path is 404, any other method 405. No endpoint changes anything.
//! - A request head is at most [`MAX_HEAD_BYTES`] and must arrive whole within
//!   [`READ_TIMEOUT`], a response be read whole within [`WRITE_TIMEOUT`] (and each event of
//!   a stream within it); a request with a body is refused. At most [`MAX_CONNECTIONS`]
//!   connections at once (503 past that).
//! - A watch that has ended (as its store records, or killed: no watch writes its directory)
//!   is said so on the page, and its viewers let go: a stream gives the history with the end
//!   and closes.
//! - The watch never waits for a viewer: publishing puts each event on every viewer's queue
//!   (at most [`QUEUE_EVENTS`] windows; past that the oldest is dropped for that viewer and
//!   its page says how many) and wakes that viewer's own thread, which writes. A newer picture
//!   replaces an older one still queued.
//! - Every response forbids the page any request to another server
//!   (`Content-Security-Policy: default-src 'self'`).

use crate::error::{Error, Result};
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Duration;

/// The address served when none is named: this machine only.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:8080";
/// Bytes of a request head, at most.
pub const MAX_HEAD_BYTES: usize = 8 * 1024;
/// Connections open at once, at most (viewers and page loads together).
pub const MAX_CONNECTIONS: usize = 64;
/// Windows queued for one viewer before its oldest is dropped.
pub const QUEUE_EVENTS: usize = 256;
/// How long a request head may take to arrive.
pub const READ_TIMEOUT: Duration = Duration::from_secs(5);
/// How long a write to a viewer may block before the viewer is given up.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(10);
/// How often the accepting thread looks whether the server is stopping.
const ACCEPT_POLL: Duration = Duration::from_millis(25);
/// How long the end of a watch waits for its viewers to be told.
const END_GRACE: Duration = Duration::from_secs(3);
/// A comment sent to an idle viewer this often, so a viewer that went away is noticed.
const KEEP_ALIVE: Duration = Duration::from_secs(15);

const PAGE_HTML: &str = include_str!("page/index.html");
const PAGE_JS: &str = include_str!("page/page.js");
const PAGE_CSS: &str = include_str!("page/page.css");

/// Headers of every response: nothing the page loads may come from elsewhere.
const SAFE_HEADERS: &str = "Content-Security-Policy: default-src 'self'; img-src 'self' data:; base-uri 'none'; form-action 'none'; frame-ancestors 'none'\r\nX-Content-Type-Options: nosniff\r\nReferrer-Policy: no-referrer\r\nCache-Control: no-store\r\n";

/// What the page is told of a watch: its stored meta, the risk its advice keeps below, and
/// each law's formula and parameters with their units (in the record's torque unit).
pub fn page_meta(meta: &super::store::WatchMeta) -> serde_json::Value {
    let unit = meta.torque_unit.label();
    let laws: Vec<serde_json::Value> = meta.settings["laws"]
        .as_array()
        .map(|laws| {
            laws.iter()
                .filter_map(|l| l.as_str()?.parse::<crate::laws::Law>().ok())
                .map(|law| {
                    serde_json::json!({
                        "name": law.name(),
                        "title": law.title(),
                        "colour": law.colour_hex(),
                        "formula": law.formula(),
                        "params": law.params().iter().map(|p| serde_json::json!({
                            "name": p.name,
                            "unit": crate::report::plot::unit(p, unit),
                        })).collect::<Vec<_>>(),
                    })
                })
                .collect()
        })
        .unwrap_or_default();
    serde_json::json!({
        "source": meta.source,
        "window_s": meta.window_s,
        "step_s": meta.step_s,
        "rate_hz": meta.rate_hz,
        "torque_unit": meta.torque_unit,
        "risk": meta.settings["risk"],
        "criterion": super::store::criterion_words(&meta.settings),
        "laws": laws,
        "probability_scale": crate::report::plot::PROBABILITY_SCALE
            .iter()
            .map(|(p, c)| serde_json::json!([p, format!("#{c:06x}")]))
            .collect::<Vec<_>>(),
        "bitrock_version": meta.bitrock_version,
        // A watch of surface channels: its windows have no bit channels to draw.
        "surface": meta.surface.is_some(),
    })
}

/// What the watch has said so far, as JSON texts (kept as sent: a late viewer gets the same).
#[derive(Default)]
struct History {
    meta: Arc<str>,
    updates: Vec<Arc<str>>,
    view: Option<Arc<str>>,
    ended: Option<Arc<str>>,
}

impl History {
    /// The history as one JSON object: `{"meta", "updates", "view", "ended"}`.
    fn json(&self) -> String {
        format!(
            "{{\"meta\":{},\"updates\":[{}],\"view\":{},\"ended\":{}}}",
            if self.meta.is_empty() { "null" } else { &self.meta },
            self.updates.iter().map(|u| &**u).collect::<Vec<_>>().join(","),
            self.view.as_deref().unwrap_or("null"),
            self.ended.as_deref().unwrap_or("null")
        )
    }
}

/// One event for a viewer.
#[derive(Clone)]
enum Event {
    Meta(Arc<str>),
    Update(Arc<str>),
    View(Arc<str>),
    End(Arc<str>),
}

/// One viewer's queue, filled by the watch and emptied by the viewer's thread.
#[derive(Default)]
struct Queue {
    events: VecDeque<Event>,
    /// Windows dropped since the viewer's thread last wrote.
    dropped: u64,
}

#[derive(Default)]
struct Viewer {
    queue: Mutex<Queue>,
    ready: Condvar,
}

/// What the accepting thread, the viewers' threads and the publisher share.
#[derive(Default)]
struct Hub {
    history: Mutex<History>,
    viewers: Mutex<Vec<Arc<Viewer>>>,
    connections: AtomicUsize,
    stopping: AtomicBool,
}

/// A running server of one watch's page.
pub struct Server {
    address: SocketAddr,
    hub: Arc<Hub>,
    accepting: Option<std::thread::JoinHandle<()>>,
}

impl Server {
    /// Serves the page at `address` (`HOST:PORT`; port 0 takes a free one) for a watch whose
    /// meta (source, settings, windows) is the JSON `meta`. A bad or busy address is refused
    /// naming `field`.
    pub fn start(address: &str, field: &'static str, meta: &serde_json::Value) -> Result<Self> {
        let listener = TcpListener::bind(address).map_err(|e| {
            Error::setting(
                field,
                format!("cannot serve at {address}: {e} (give HOST:PORT, e.g. {DEFAULT_ADDRESS})"),
            )
        })?;
        let address = listener
            .local_addr()
            .map_err(|e| Error::setting(field, e.to_string()))?;
        listener
            .set_nonblocking(true)
            .map_err(|e| Error::setting(field, e.to_string()))?;
        let hub = Arc::new(Hub::default());
        hub.history.lock().expect("unpoisoned").meta = meta.to_string().into();
        let accepting = {
            let hub = hub.clone();
            std::thread::Builder::new()
                .name("bitrock-serve".into())
                .spawn(move || accept(listener, hub))
                .map_err(|e| Error::setting(field, format!("cannot start the server: {e}")))?
        };
        Ok(Self {
            address,
            hub,
            accepting: Some(accepting),
        })
    }

    /// What the page says of the watch (`page_meta`): its source, windows and laws.
    pub fn set_meta(&self, meta: &serde_json::Value) {
        let meta: Arc<str> = meta.to_string().into();
        let mut history = self.hub.history.lock().expect("unpoisoned");
        history.meta = meta.clone();
        self.hub.send(Event::Meta(meta));
    }

    /// The address served (the port chosen where 0 was asked).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Viewers connected to the stream now.
    pub fn viewers(&self) -> usize {
        self.hub.viewers.lock().expect("unpoisoned").len()
    }

    /// Sends a window's update (and, where given, its picture) to every viewer.
    pub fn publish(&self, update: &super::Update, view: Option<&super::view::View>) {
        let update: Arc<str> = serde_json::to_string(update).expect("an update serialises").into();
        let view: Option<Arc<str>> = view.map(|v| serde_json::to_string(v).expect("a view serialises").into());
        // Queued under the history's lock: a viewer that connects now finds the window either
        // in its history or in its queue, never in both.
        let mut history = self.hub.history.lock().expect("unpoisoned");
        history.updates.push(update.clone());
        if let Some(view) = &view {
            history.view = Some(view.clone());
        }
        self.hub.send(Event::Update(update));
        if let Some(view) = view {
            self.hub.send(Event::View(view));
        }
    }

    /// Tells every viewer the watch has ended (`ended`, JSON, its `said` the page's status)
    /// and lets them go (each stream is closed once its queue is written); the page is still
    /// served, and a viewer who comes later gets the history with its end and is let go too.
    pub fn mark_ended(&self, ended: &serde_json::Value) {
        let ended: Arc<str> = ended.to_string().into();
        let mut history = self.hub.history.lock().expect("unpoisoned");
        history.ended = Some(ended.clone());
        self.hub.send(Event::End(ended));
    }

    /// Whether the page says the watch has ended.
    pub fn is_ended(&self) -> bool {
        self.hub.history.lock().expect("unpoisoned").ended.is_some()
    }

    /// Tells every viewer the watch has ended ([`Self::mark_ended`]) and stops serving: no new
    /// connection is taken.
    pub fn end(mut self, ended: &serde_json::Value) {
        self.mark_ended(ended);
        self.stop();
        // The viewers' threads write what is queued and close; a stalled one is not waited
        // for past the deadline.
        let deadline = std::time::Instant::now() + END_GRACE;
        while std::time::Instant::now() < deadline && self.viewers() > 0 {
            std::thread::sleep(ACCEPT_POLL);
        }
    }

    fn stop(&mut self) {
        self.hub.stopping.store(true, Ordering::SeqCst);
        if let Some(accepting) = self.accepting.take() {
            let _ = accepting.join();
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop();
        // Wake every viewer's thread: each ends its stream.
        for viewer in self.hub.viewers.lock().expect("unpoisoned").iter() {
            viewer.ready.notify_all();
        }
    }
}

impl Hub {
    /// Puts `event` on every viewer's queue, dropping that viewer's oldest window where its
    /// queue is full, and a picture still queued where a newer one comes.
    fn send(&self, event: Event) {
        for viewer in self.viewers.lock().expect("unpoisoned").iter() {
            let mut queue = viewer.queue.lock().expect("unpoisoned");
            match &event {
                Event::View(_) => queue.events.retain(|e| !matches!(e, Event::View(_))),
                Event::Update(_) => {
                    let updates = queue.events.iter().filter(|e| matches!(e, Event::Update(_))).count();
                    if updates >= QUEUE_EVENTS
                        && let Some(oldest) = queue.events.iter().position(|e| matches!(e, Event::Update(_)))
                    {
                        queue.events.remove(oldest);
                        queue.dropped += 1;
                    }
                }
                Event::Meta(_) => queue.events.retain(|e| !matches!(e, Event::Meta(_))),
                Event::End(_) => {}
            }
            queue.events.push_back(event.clone());
            viewer.ready.notify_one();
        }
    }
}

/// Takes connections until the server stops, each on a thread of its own.
fn accept(listener: TcpListener, hub: Arc<Hub>) {
    while !hub.stopping.load(Ordering::SeqCst) {
        match listener.accept() {
            Ok((stream, _)) => {
                let _ = stream.set_nonblocking(false);
                if hub.connections.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
                    hub.connections.fetch_sub(1, Ordering::SeqCst);
                    let mut stream = stream;
                    let _ = respond(
                        &mut stream,
                        "503 Service Unavailable",
                        "text/plain; charset=utf-8",
                        b"too many connections\n",
                        false,
                    );
                    continue;
                }
                let shared = hub.clone();
                let spawned = std::thread::Builder::new()
                    .name("bitrock-viewer".into())
                    .spawn(move || {
                        let _ = serve_connection(stream, &shared);
                        shared.connections.fetch_sub(1, Ordering::SeqCst);
                    });
                if spawned.is_err() {
                    // No thread for it: the connection is closed as it drops, and not counted.
                    hub.connections.fetch_sub(1, Ordering::SeqCst);
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => std::thread::sleep(ACCEPT_POLL),
            Err(_) => std::thread::sleep(ACCEPT_POLL),
        }
    }
}

/// What a request asked for.
#[derive(Debug, PartialEq)]
enum Asked {
    /// A path, and whether only the head of the answer is wanted (HEAD).
    Get(String, bool),
    /// Refused: the status line and why.
    Refused(&'static str, &'static str),
}

/// Reads one request head (bounded in size, and in time as a whole: a client that trickles
/// it is let go after [`READ_TIMEOUT`]) and says what it asks for.
fn read_request(stream: &mut TcpStream) -> std::io::Result<Asked> {
    let deadline = std::time::Instant::now() + READ_TIMEOUT;
    let mut buf = vec![0u8; MAX_HEAD_BYTES];
    let mut filled = 0;
    loop {
        if filled == buf.len() {
            return Ok(Asked::Refused(
                "431 Request Header Fields Too Large",
                "the request head is too long\n",
            ));
        }
        stream.set_read_timeout(Some(until(deadline)?))?;
        let n = stream.read(&mut buf[filled..])?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        filled += n;
        let mut headers = [httparse::EMPTY_HEADER; 32];
        let mut request = httparse::Request::new(&mut headers);
        match request.parse(&buf[..filled]) {
            Ok(httparse::Status::Partial) => continue,
            Ok(httparse::Status::Complete(_)) => return Ok(asked(&request)),
            Err(httparse::Error::TooManyHeaders) => {
                return Ok(Asked::Refused(
                    "431 Request Header Fields Too Large",
                    "too many headers\n",
                ));
            }
            Err(_) => return Ok(Asked::Refused("400 Bad Request", "not an HTTP request\n")),
        }
    }
}

/// What a parsed request head asks for: a GET or HEAD of a path without a body.
fn asked(request: &httparse::Request<'_, '_>) -> Asked {
    let head_only = match request.method {
        Some("GET") => false,
        Some("HEAD") => true,
        _ => return Asked::Refused("405 Method Not Allowed", "this server only reads: GET\n"),
    };
    let has_body = request.headers.iter().any(|h| {
        h.name.eq_ignore_ascii_case("transfer-encoding")
            || (h.name.eq_ignore_ascii_case("content-length") && h.value.iter().any(|&b| b != b'0'))
    });
    if has_body {
        return Asked::Refused("413 Content Too Large", "a request to this server has no body\n");
    }
    let path = request.path.unwrap_or("/");
    let path = path.split(['?', '#']).next().unwrap_or("/");
    Asked::Get(path.to_string(), head_only)
}

/// Answers one connection: a file of the page, the history, or the stream of events.
fn serve_connection(mut stream: TcpStream, hub: &Hub) -> std::io::Result<()> {
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let (path, head_only) = match read_request(&mut stream)? {
        Asked::Get(path, head_only) => (path, head_only),
        Asked::Refused(status, why) => {
            return respond(&mut stream, status, "text/plain; charset=utf-8", why.as_bytes(), false);
        }
    };
    let file = |body: &'static str, content_type| (content_type, std::borrow::Cow::Borrowed(body.as_bytes()));
    let (content_type, body) = match path.as_str() {
        "/" | "/index.html" => file(PAGE_HTML, "text/html; charset=utf-8"),
        "/page.js" => file(PAGE_JS, "text/javascript; charset=utf-8"),
        "/page.css" => file(PAGE_CSS, "text/css; charset=utf-8"),
        "/state.json" => {
            let json = hub.history.lock().expect("unpoisoned").json();
            ("application/json", std::borrow::Cow::Owned(json.into_bytes()))
        }
        "/events" if !head_only => return stream_events(stream, hub),
        "/events" => ("text/event-stream", std::borrow::Cow::Borrowed(&b""[..])),
        _ => {
            let why = b"not found: this server serves /, /events and /state.json\n";
            return respond(
                &mut stream,
                "404 Not Found",
                "text/plain; charset=utf-8",
                why,
                head_only,
            );
        }
    };
    respond(&mut stream, "200 OK", content_type, &body, head_only)
}

/// The time left before `deadline`, or a timed-out error once it has passed.
fn until(deadline: std::time::Instant) -> std::io::Result<Duration> {
    let left = deadline.saturating_duration_since(std::time::Instant::now());
    if left.is_zero() {
        return Err(std::io::ErrorKind::TimedOut.into());
    }
    Ok(left)
}

/// Bytes written to a client at a time: each piece within the time left to the response.
const WRITE_PIECE: usize = 64 * 1024;

/// Writes a whole response (its head alone for a HEAD request) within [`WRITE_TIMEOUT`] as a
/// whole (a client that reads slowly is let go), and closes.
fn respond(
    stream: &mut TcpStream,
    status: &str,
    content_type: &str,
    body: &[u8],
    head_only: bool,
) -> std::io::Result<()> {
    let head = format!(
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\nConnection: close\r\n{SAFE_HEADERS}\r\n",
        body.len()
    );
    let deadline = std::time::Instant::now() + WRITE_TIMEOUT;
    let body = if head_only { &[][..] } else { body };
    for piece in head.as_bytes().chunks(WRITE_PIECE).chain(body.chunks(WRITE_PIECE)) {
        stream.set_write_timeout(Some(until(deadline)?))?;
        stream.write_all(piece)?;
    }
    stream.flush()
}

/// The stream of one viewer: the history first, then each event as the watch publishes it,
/// until the watch ends, the server stops or the viewer goes.
fn stream_events(mut stream: TcpStream, hub: &Hub) -> std::io::Result<()> {
    let viewer = Arc::new(Viewer::default());
    // Registered under the history's lock: no window is both in the history and queued, none
    // is missed. A watch that has ended gives its history, its end with it, and lets go.
    let (history, ended) = {
        let history = hub.history.lock().expect("unpoisoned");
        if history.ended.is_none() {
            hub.viewers.lock().expect("unpoisoned").push(viewer.clone());
        }
        (history.json(), history.ended.is_some())
    };
    let result = (|| {
        let head =
            format!("HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nConnection: close\r\n{SAFE_HEADERS}\r\n");
        stream.write_all(head.as_bytes())?;
        write_event(&mut stream, "history", &history)?;
        if ended {
            return Ok(());
        }
        loop {
            let (events, dropped) = {
                let mut queue = viewer.queue.lock().expect("unpoisoned");
                while queue.events.is_empty() && !hub.stopping.load(Ordering::SeqCst) {
                    let (q, timeout) = viewer.ready.wait_timeout(queue, KEEP_ALIVE).expect("unpoisoned");
                    queue = q;
                    if timeout.timed_out() && queue.events.is_empty() {
                        break;
                    }
                }
                let events: Vec<Event> = queue.events.drain(..).collect();
                (events, std::mem::take(&mut queue.dropped))
            };
            if dropped > 0 {
                write_event(&mut stream, "dropped", &format!("{{\"windows\":{dropped}}}"))?;
            }
            if events.is_empty() {
                if hub.stopping.load(Ordering::SeqCst) {
                    return Ok(());
                }
                stream.write_all(b": still here\n\n")?;
                stream.flush()?;
                continue;
            }
            for event in events {
                match event {
                    Event::Meta(json) => write_event(&mut stream, "meta", &json)?,
                    Event::Update(json) => write_event(&mut stream, "update", &json)?,
                    Event::View(json) => write_event(&mut stream, "view", &json)?,
                    Event::End(json) => {
                        write_event(&mut stream, "end", &json)?;
                        return Ok(());
                    }
                }
            }
        }
    })();
    hub.viewers
        .lock()
        .expect("unpoisoned")
        .retain(|v| !Arc::ptr_eq(v, &viewer));
    result
}

/// One server-sent event (JSON holds no newline).
fn write_event(stream: &mut TcpStream, name: &str, json: &str) -> std::io::Result<()> {
    debug_assert!(!json.contains('\n'));
    stream.write_all(format!("event: {name}\ndata: {json}\n\n").as_bytes())?;
    stream.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(addr: SocketAddr, text: &[u8]) -> String {
        let mut s = TcpStream::connect(addr).unwrap();
        s.write_all(text).unwrap();
        let mut out = String::new();
        let _ = s.read_to_string(&mut out);
        out
    }

    /// A client that trickles its request head, a byte a second (each read well within the
    /// read timeout), is let go once the head as a whole has taken the timeout; a watch marked
    /// ended gives a new viewer its history with the end and closes the stream.
    #[test]
    fn a_trickled_head_is_let_go_and_an_ended_watch_lets_its_viewers_go() {
        let server = Server::start("127.0.0.1:0", "serve", &serde_json::json!({"source": "x"})).unwrap();
        let addr = server.address();
        let mut s = TcpStream::connect(addr).unwrap();
        let started = std::time::Instant::now();
        let mut closed = false;
        for byte in b"GET / HTTP/1.1\r\nX-Slow: ".iter().cycle().take(60) {
            if s.write_all(&[*byte]).is_err() {
                closed = true;
                break;
            }
            std::thread::sleep(Duration::from_secs(1));
            if started.elapsed() > READ_TIMEOUT + Duration::from_secs(3) {
                let mut rest = Vec::new();
                s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
                closed = s.read_to_end(&mut rest).is_ok() && rest.is_empty();
                break;
            }
        }
        assert!(
            closed,
            "the trickling client is still held after {:?}",
            started.elapsed()
        );

        server.mark_ended(&serde_json::json!({"said": "the watch has ended"}));
        let events = request(addr, b"GET /events HTTP/1.1\r\n\r\n");
        assert!(
            events.contains("event: history") && events.contains("the watch has ended"),
            "{events}"
        );
        assert_eq!(server.viewers(), 0);
    }

    #[test]
    fn the_server_only_reads_and_refuses_what_it_does_not_serve() {
        let server = Server::start("127.0.0.1:0", "serve", &serde_json::json!({"source": "x"})).unwrap();
        let addr = server.address();
        let page = request(addr, b"GET / HTTP/1.1\r\nHost: x\r\n\r\n");
        assert!(page.starts_with("HTTP/1.1 200 OK"), "{page}");
        assert!(page.contains("Content-Security-Policy: default-src 'self'"));
        assert!(page.contains("page.js"));
        let head = request(addr, b"HEAD /page.js HTTP/1.1\r\n\r\n");
        assert!(
            head.starts_with("HTTP/1.1 200 OK") && head.ends_with("\r\n\r\n"),
            "{head}"
        );
        for (text, status) in [
            (&b"POST / HTTP/1.1\r\nContent-Length: 0\r\n\r\n"[..], "405"),
            (b"GET /../../etc/passwd HTTP/1.1\r\n\r\n", "404"),
            (b"GET /page.js/../Cargo.toml HTTP/1.1\r\n\r\n", "404"),
            (b"GET / HTTP/1.1\r\nContent-Length: 5\r\n\r\nhello", "413"),
            (b"NOT HTTP AT ALL\r\n\r\n", "400"),
        ] {
            let answer = request(addr, text);
            assert!(answer.starts_with(&format!("HTTP/1.1 {status}")), "{answer}");
        }
        // A head past the bound.
        let mut long = b"GET / HTTP/1.1\r\nX: ".to_vec();
        long.extend(std::iter::repeat_n(b'a', MAX_HEAD_BYTES));
        assert!(request(addr, &long).starts_with("HTTP/1.1 431"));
        let state = request(addr, b"GET /state.json HTTP/1.1\r\n\r\n");
        let body = state.split("\r\n\r\n").nth(1).unwrap();
        let v: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(v["meta"]["source"], "x");
        assert_eq!(v["updates"], serde_json::json!([]));
    }

    #[test]
    fn a_stalled_viewer_loses_its_oldest_windows_and_is_told() {
        let hub = Hub::default();
        let viewer = Arc::new(Viewer::default());
        hub.viewers.lock().unwrap().push(viewer.clone());
        for k in 0..QUEUE_EVENTS + 5 {
            hub.send(Event::Update(format!("{k}").into()));
            hub.send(Event::View(format!("view {k}").into()));
        }
        let queue = viewer.queue.lock().unwrap();
        assert_eq!(queue.dropped, 5);
        let updates: Vec<&str> = queue
            .events
            .iter()
            .filter_map(|e| match e {
                Event::Update(j) => Some(&**j),
                _ => None,
            })
            .collect();
        assert_eq!(updates.len(), QUEUE_EVENTS);
        assert_eq!(updates[0], "5");
        // Only the newest picture waits.
        let views: Vec<&str> = queue
            .events
            .iter()
            .filter_map(|e| match e {
                Event::View(j) => Some(&**j),
                _ => None,
            })
            .collect();
        assert_eq!(views, [format!("view {}", QUEUE_EVENTS + 4)]);
    }

    #[test]
    fn past_the_connection_bound_a_connection_is_told_to_come_back() {
        let server = Server::start("127.0.0.1:0", "serve", &serde_json::json!({})).unwrap();
        let addr = server.address();
        // Streams held open count against the bound.
        let mut held = Vec::new();
        for _ in 0..MAX_CONNECTIONS {
            let mut s = TcpStream::connect(addr).unwrap();
            s.write_all(b"GET /events HTTP/1.1\r\n\r\n").unwrap();
            let mut first = [0u8; 15];
            s.read_exact(&mut first).unwrap();
            assert_eq!(&first, b"HTTP/1.1 200 OK");
            held.push(s);
        }
        assert_eq!(server.viewers(), MAX_CONNECTIONS);
        assert!(request(addr, b"GET / HTTP/1.1\r\n\r\n").starts_with("HTTP/1.1 503"));
        drop(held);
    }
}
