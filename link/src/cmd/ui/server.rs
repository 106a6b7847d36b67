//! The cockpit's HTTP and websocket server: hyper's HTTP/1 connections
//! under axum's router and websocket, on a small tokio runtime of its own
//! (the link's thread stays as it is: blocking, one request at a time).
//!
//! What a client can hold is bounded: [`MAX_CONNECTIONS`] connections at
//! once (more are closed as they come), [`HEAD_TIME`] to send a request's
//! head and [`HEAD_BYTES`] for it, [`CONNECTION_TIME`] for a whole plain
//! request, [`MAX_PAGES`] websockets, and each page's outgoing messages
//! ([`Tab`]): a tab that does not read loses telemetry (counted, and told
//! when it reads again), keeps only the newest state, and is closed (it
//! reconnects) when its events pile up.

use super::{answer, Command, Shared, PAGE};
use anyhow::{Context, Result};
use axum::body::Body;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{FromRequest, Request, State};
use axum::http::{header, HeaderMap, HeaderValue, Method, StatusCode};
use axum::response::{IntoResponse, Response};
use futures_util::{SinkExt, StreamExt};
use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// Connections open at once; more are closed as they are accepted.
pub(crate) const MAX_CONNECTIONS: usize = 256;
/// Pages (websockets) open at once; more are refused (503).
pub(crate) const MAX_PAGES: usize = 16;
/// Time to send a request's head: a client that trickles it is closed.
pub(crate) const HEAD_TIME: Duration = Duration::from_secs(5);
/// A request head's largest size, bytes (a browser's fits in 8 KiB);
/// a larger one is refused (431).
pub(crate) const HEAD_BYTES: usize = 16 * 1024;
/// Time for a whole request (not a websocket, once upgraded).
pub(crate) const CONNECTION_TIME: Duration = Duration::from_secs(30);
/// The socket's send buffer, bytes (the kernel doubles it).
const SEND_BUFFER_BYTES: usize = 32 * 1024;
/// Telemetry messages (about 30 a second) waiting for a page; older ones
/// are dropped, and counted.
const TAB_TELEMETRY: usize = 32;
/// Events (answers, hops, notices) waiting for a page; a page this far
/// behind is closed, and reconnects to the current state.
const TAB_EVENTS: usize = 256;

/// A page's commands waiting for the link's thread; one more is refused
/// at once (Disarm does not wait in this line), and one page's flood
/// does not hold up another's.
pub(crate) const PAGE_COMMANDS: usize = 8;
/// The line's length: every page's share.
pub(crate) const COMMANDS_WAITING: usize = MAX_PAGES * PAGE_COMMANDS;

/// The session cookie's name: the token's stand-in after the first load,
/// so that the token leaves the address bar.
const COOKIE: &str = "hopper_session";

/// What the server checks requests against and hands pages to.
pub(crate) struct Server {
    /// The token printed at start.
    pub token: String,
    /// The session cookie's value, given with the page.
    pub session: String,
    /// The names a browser may use for this server (its `Host`).
    pub hosts: Vec<String>,
    /// What the link's thread and the pages share.
    pub shared: Shared,
    /// The pages' commands to the link's thread.
    pub commands: std::sync::mpsc::SyncSender<Command>,
}

/// Serves the cockpit on `listener` from a thread of its own.
pub(crate) fn spawn(listener: std::net::TcpListener, server: Server) -> Result<()> {
    listener.set_nonblocking(true)?;
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .max_blocking_threads(4)
        .thread_name("cockpit-http")
        .enable_all()
        .build()
        .context("the cockpit's server runtime")?;
    std::thread::Builder::new()
        .name("cockpit-accept".into())
        .spawn(move || rt.block_on(accept(listener, Arc::new(server))))?;
    Ok(())
}

async fn accept(listener: std::net::TcpListener, server: Arc<Server>) {
    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
        return;
    };
    let limit = Arc::new(tokio::sync::Semaphore::new(MAX_CONNECTIONS));
    let app = axum::Router::new().fallback(handle).with_state(server);
    loop {
        let Ok((stream, _)) = listener.accept().await else {
            continue;
        };
        let Ok(permit) = limit.clone().try_acquire_owned() else {
            drop(stream);
            continue;
        };
        // Small frames (a Disarm's answer) go out at once: with Nagle's
        // algorithm one waited for the browser's delayed acknowledgement,
        // about 40 ms, every few Disarms.
        let _ = stream.set_nodelay(true);
        // What a page that does not read can leave in the kernel.
        let _ = socket2::SockRef::from(&stream).set_send_buffer_size(SEND_BUFFER_BYTES);
        let service = hyper_util::service::TowerToHyperService::new(app.clone());
        tokio::spawn(async move {
            let mut http = hyper::server::conn::http1::Builder::new();
            http.timer(hyper_util::rt::TokioTimer::new())
                .header_read_timeout(HEAD_TIME)
                .max_buf_size(HEAD_BYTES)
                .keep_alive(false);
            let conn = http
                .serve_connection(hyper_util::rt::TokioIo::new(stream), service)
                .with_upgrades();
            // (Once a websocket is upgraded, the connection's future ends;
            // the page goes on in its own task.)
            let _ = tokio::time::timeout(CONNECTION_TIME, conn).await;
            drop(permit);
        });
    }
}

/// A plain answer.
fn plain(status: StatusCode, body: &str) -> Response {
    (
        status,
        [
            (header::CONTENT_TYPE, "text/plain"),
            (header::CACHE_CONTROL, "no-store"),
        ],
        body.to_string(),
    )
        .into_response()
}

/// Every request: the page, or its websocket, once checked.
async fn handle(State(server): State<Arc<Server>>, req: Request) -> Response {
    let headers = req.headers();
    let one = |name: header::HeaderName| headers.get(&name).and_then(|v| v.to_str().ok());
    let websocket = one(header::UPGRADE).is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    // One `Host`, not a first one trusted and a second ignored; a
    // websocket's handshake with its key (16 bytes in base64).
    let hosts_given = headers.get_all(header::HOST).iter().count();
    let key_ok = one(header::SEC_WEBSOCKET_KEY).is_some_and(|k| {
        data_encoding::BASE64
            .decode(k.trim().as_bytes())
            .is_ok_and(|b| b.len() == 16)
    });
    if hosts_given > 1 || (websocket && !key_ok) {
        return plain(StatusCode::BAD_REQUEST, "bad request\n");
    }
    let target = req
        .uri()
        .path_and_query()
        .map_or("/", |p| p.as_str())
        .to_string();
    if let Some(why) = refusal(
        one(header::HOST),
        one(header::ORIGIN),
        &target,
        session_cookie(headers),
        &server,
        websocket,
    ) {
        return plain(StatusCode::FORBIDDEN, &format!("refused: {why}\n"));
    }
    match (req.method(), req.uri().path(), websocket) {
        (&Method::GET, "/", false) => {
            let cookie = format!(
                "{COOKIE}={}; Path=/; HttpOnly; SameSite=Strict",
                server.session
            );
            let mut r = Response::new(Body::from(page_html()));
            let h = r.headers_mut();
            h.insert(
                header::CONTENT_TYPE,
                HeaderValue::from_static("text/html; charset=utf-8"),
            );
            h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
            h.insert(
                header::REFERRER_POLICY,
                HeaderValue::from_static("no-referrer"),
            );
            h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
            if let Ok(v) = HeaderValue::from_str(&cookie) {
                h.insert(header::SET_COOKIE, v);
            }
            r
        }
        (&Method::GET, "/ws", true) => {
            if server.shared.live.load(Ordering::Relaxed) >= MAX_PAGES {
                return plain(
                    StatusCode::SERVICE_UNAVAILABLE,
                    &format!("refused: {MAX_PAGES} pages are open already\n"),
                );
            }
            match WebSocketUpgrade::from_request(req, &()).await {
                Ok(ws) => ws.on_upgrade(move |socket| page(socket, server)),
                Err(rejection) => rejection.into_response(),
            }
        }
        _ => plain(StatusCode::NOT_FOUND, "not found\n"),
    }
}

/// The page with the plotting library and the bring-up order inlined
/// (nothing loaded from elsewhere).
fn page_html() -> &'static str {
    static HTML: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    HTML.get_or_init(|| {
        PAGE.replace(
            "/*UPLOT_CSS*/",
            include_str!("../vendor/uplot/uPlot.min.css"),
        )
        .replace(
            "/*UPLOT_JS*/",
            include_str!("../vendor/uplot/uPlot.iife.min.js"),
        )
        .replace(
            "/*BRINGUP_STEPS*/[]",
            &hopper_link::bringup::cockpit_steps_js(),
        )
        // The planar machine's drawing: the one of `hopper-sim planar`'s
        // recorded and live pages.
        .replace(
            "/*PLANAR_DRAW*/",
            include_str!("../../../../study/src/planar_draw.js"),
        )
    })
}

/// The session cookie's value, if the request has one.
fn session_cookie(headers: &HeaderMap) -> Option<&str> {
    headers
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .find_map(|kv| kv.trim().strip_prefix(COOKIE)?.strip_prefix('='))
}

/// The value of query parameter `key` in `target` (`/ws?token=...`).
fn query<'a>(target: &'a str, key: &str) -> Option<&'a str> {
    target
        .split_once('?')?
        .1
        .split('&')
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
}

/// Why a request is refused, if it is: the `Host` is not this server's,
/// neither the token nor the session cookie is given, or (a websocket)
/// the `Origin` is not this page's.
pub(crate) fn refusal(
    host: Option<&str>,
    origin: Option<&str>,
    target: &str,
    cookie: Option<&str>,
    server: &Server,
    websocket: bool,
) -> Option<&'static str> {
    let Some(host) = host.filter(|h| server.hosts.iter().any(|x| x == h)) else {
        return Some("wrong Host");
    };
    if query(target, "token") != Some(server.token.as_str())
        && cookie != Some(server.session.as_str())
    {
        return Some("no valid token");
    }
    if websocket && origin != Some(&format!("http://{host}")) {
        return Some("wrong Origin");
    }
    None
}

/// The names a browser may use for this server (its `Host`): its
/// address, `localhost` on loopback, each without the port too when the
/// port is HTTP's default 80 (browsers leave `:80` out).
pub(crate) fn hosts_for(bound: SocketAddr) -> Vec<String> {
    let mut names = vec![bound.ip().to_string()];
    if bound.ip().is_loopback() {
        names.push("localhost".into());
    }
    let mut hosts: Vec<String> = names
        .iter()
        .map(|n| match bound {
            SocketAddr::V6(_) if n != "localhost" => format!("[{n}]:{}", bound.port()),
            _ => format!("{n}:{}", bound.port()),
        })
        .collect();
    if bound.port() == 80 {
        hosts.extend(names.iter().map(|n| match bound {
            SocketAddr::V6(_) if n != "localhost" => format!("[{n}]"),
            _ => n.clone(),
        }));
    }
    hosts
}

/// A random secret: 128 bits as hex.
pub(crate) fn secret() -> Result<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("no random token: {e}"))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// What waits to go to one page, bounded: telemetry (the oldest dropped,
/// counted), the newest of each state message (`state`, `thermal`,
/// `params`: each replaces the last), and events (answers, hops, faults,
/// notices; too many and the page is closed). Events and state messages
/// go in the order they came (a state from before the robot was lost must
/// not follow the `lost` that supersedes it), each numbered as it comes.
#[derive(Default)]
struct Outbox {
    telemetry: VecDeque<String>,
    latest: Vec<(String, u64, String)>,
    events: VecDeque<(u64, String)>,
    /// The next message's number.
    seq: u64,
    /// Telemetry messages dropped, and how many the page was told of.
    dropped: u64,
    told: u64,
    /// Too many events unread, or the socket gone: nothing more is kept.
    closed: bool,
}

/// One page's outgoing messages, shared by the link's thread (which
/// pushes, never waits) and the page's task (which sends).
#[derive(Clone, Default)]
pub(crate) struct Tab {
    out: Arc<Mutex<Outbox>>,
    wake: Arc<tokio::sync::Notify>,
    /// Its commands waiting for the link's thread.
    waiting: Arc<std::sync::atomic::AtomicUsize>,
}

impl Tab {
    /// Queues an answer (an event) for the page; `Err` once the page is
    /// gone.
    pub(crate) fn send(&self, text: String) -> Result<(), ()> {
        self.push("result", text)
    }

    /// Queues `text`, a message of type `kind`, for the page (the type
    /// says how it is kept); `Err` once the page is gone.
    pub(crate) fn push(&self, kind: &str, text: String) -> Result<(), ()> {
        {
            let Ok(mut o) = self.out.lock() else {
                return Err(());
            };
            if o.closed {
                return Err(());
            }
            match kind {
                "telemetry" => {
                    if o.telemetry.len() >= TAB_TELEMETRY {
                        o.telemetry.pop_front();
                        o.dropped += 1;
                    }
                    o.telemetry.push_back(text);
                }
                "state" | "thermal" | "params" => {
                    let seq = o.seq;
                    o.seq += 1;
                    match o.latest.iter_mut().find(|(k, _, _)| k == kind) {
                        Some(slot) => (slot.1, slot.2) = (seq, text),
                        None => o.latest.push((kind.to_string(), seq, text)),
                    }
                }
                _ if o.events.len() >= TAB_EVENTS => {
                    *o = Outbox {
                        closed: true,
                        ..Outbox::default()
                    };
                }
                _ => {
                    let seq = o.seq;
                    o.seq += 1;
                    o.events.push_back((seq, text));
                }
            }
        }
        self.wake.notify_one();
        Ok(())
    }

    /// Everything waiting, in the order to send it (events and the state
    /// messages in the order they came, then telemetry), with a note of
    /// newly dropped telemetry; `None` once the page is to be closed.
    fn take(&self) -> Option<Vec<String>> {
        let mut o = self.out.lock().ok()?;
        if o.closed {
            return None;
        }
        let mut ordered: Vec<(u64, String)> = o.events.drain(..).collect();
        ordered.extend(o.latest.drain(..).map(|(_, seq, t)| (seq, t)));
        ordered.sort_by_key(|(seq, _)| *seq);
        let mut all: Vec<String> = ordered.into_iter().map(|(_, t)| t).collect();
        if o.dropped != o.told {
            o.told = o.dropped;
            all.push(serde_json::json!({ "type": "page", "dropped": o.dropped }).to_string());
        }
        all.extend(o.telemetry.drain(..));
        Some(all)
    }

    /// The link's thread took one of its commands.
    pub(crate) fn taken(&self) {
        let _ = self
            .waiting
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |n| n.checked_sub(1));
    }

    fn close(&self) {
        if let Ok(mut o) = self.out.lock() {
            o.closed = true;
        }
    }

    /// Whether the page is gone.
    #[cfg(test)]
    fn closed(&self) -> bool {
        self.out.lock().map_or(true, |o| o.closed)
    }
}

/// A page's websocket: its messages out, its commands in; a Disarm sent
/// to the robot from here, at once.
async fn page(socket: WebSocket, server: Arc<Server>) {
    let shared = &server.shared;
    let _live = super::Live::new(&shared.live);
    let tab = Tab::default();
    if let Ok(mut p) = shared.pages.lock() {
        p.push(tab.clone());
    }
    // The table first.
    tab.waiting.fetch_add(1, Ordering::Relaxed);
    if server
        .commands
        .try_send(Command {
            json: serde_json::json!({ "cmd": "params" }),
            reply: tab.clone(),
        })
        .is_err()
    {
        tab.taken();
    }
    let (mut sink, mut stream) = socket.split();
    let out = tab.clone();
    let writer = tokio::spawn(async move {
        loop {
            out.wake.notified().await;
            let Some(all) = out.take() else {
                let _ = sink.send(Message::Close(None)).await;
                return;
            };
            for text in all {
                if sink.send(Message::Text(text.into())).await.is_err() {
                    out.close();
                    return;
                }
            }
        }
    });
    while let Some(Ok(msg)) = stream.next().await {
        let Message::Text(t) = msg else {
            if matches!(msg, Message::Close(_)) {
                break;
            }
            continue;
        };
        let Ok(json) = serde_json::from_str::<serde_json::Value>(t.as_str()) else {
            continue;
        };
        if json["cmd"] == "disarm" {
            let s = shared.clone();
            let result = tokio::task::spawn_blocking(move || s.disarm())
                .await
                .unwrap_or_else(|e| Err(anyhow::anyhow!("disarm: {e}")))
                .map(|()| "disarmed".to_string());
            let _ = tab.send(answer(&json, result).to_string());
            continue;
        }
        let busy = |json: &serde_json::Value| {
            let e = anyhow::anyhow!(
                "refused: the cockpit has {PAGE_COMMANDS} of this page's commands waiting for the robot; send it again (Disarm does not wait)"
            );
            let _ = tab.send(answer(json, Err(e)).to_string());
        };
        if tab.waiting.fetch_add(1, Ordering::Relaxed) >= PAGE_COMMANDS {
            tab.taken();
            busy(&json);
            continue;
        }
        if let Err(std::sync::mpsc::TrySendError::Full(cmd)) = server.commands.try_send(Command {
            json,
            reply: tab.clone(),
        }) {
            tab.taken();
            busy(&cmd.json);
        }
    }
    tab.close();
    tab.wake.notify_one();
    let _ = writer.await;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_may_leave_out_the_default_port() {
        let on = |a: &str| hosts_for(a.parse().unwrap_or_else(|e| panic!("{e}")));
        assert_eq!(on("127.0.0.1:8080"), ["127.0.0.1:8080", "localhost:8080"]);
        assert_eq!(
            on("127.0.0.1:80"),
            ["127.0.0.1:80", "localhost:80", "127.0.0.1", "localhost"]
        );
        assert_eq!(on("192.168.1.5:80"), ["192.168.1.5:80", "192.168.1.5"]);
        assert_eq!(on("[::1]:8080"), ["[::1]:8080", "localhost:8080"]);
    }

    fn server() -> Server {
        Server {
            token: "abc".into(),
            session: "s3".into(),
            hosts: vec!["127.0.0.1:8080".to_string(), "localhost:8080".to_string()],
            shared: Shared::default(),
            commands: std::sync::mpsc::sync_channel(1).0,
        }
    }

    #[test]
    fn only_this_pages_requests_with_the_token_or_its_session_pass() {
        let s = server();
        let ok = |host, origin, target, ws| refusal(host, origin, target, None, &s, ws);
        assert_eq!(ok(Some("127.0.0.1:8080"), None, "/?token=abc", false), None);
        assert_eq!(
            ok(
                Some("localhost:8080"),
                Some("http://localhost:8080"),
                "/ws?token=abc",
                true
            ),
            None
        );
        // DNS rebinding: the attacker's name in Host.
        assert_eq!(
            ok(Some("evil.example:8080"), None, "/?token=abc", false),
            Some("wrong Host")
        );
        assert_eq!(ok(None, None, "/?token=abc", false), Some("wrong Host"));
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/", false),
            Some("no valid token")
        );
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/?token=abd", false),
            Some("no valid token")
        );
        // Another page in the same browser (it knows the token, say).
        assert_eq!(
            ok(
                Some("127.0.0.1:8080"),
                Some("http://evil.example"),
                "/ws?token=abc",
                true
            ),
            Some("wrong Origin")
        );
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/ws?token=abc", true),
            Some("wrong Origin")
        );
        // After the first load, the session cookie stands for the token;
        // a wrong one does not.
        let own = Some("http://127.0.0.1:8080");
        let host = Some("127.0.0.1:8080");
        assert_eq!(refusal(host, own, "/ws", Some("s3"), &s, true), None);
        assert_eq!(refusal(host, None, "/", Some("s3"), &s, false), None);
        assert_eq!(
            refusal(host, own, "/ws", Some("s4"), &s, true),
            Some("no valid token")
        );
    }

    #[test]
    fn a_page_that_does_not_read_keeps_a_bounded_queue() {
        let tab = Tab::default();
        let msg = |kind: &str, n: usize| serde_json::json!({ "type": kind, "n": n }).to_string();
        for n in 0..1000 {
            assert!(tab.push("telemetry", msg("telemetry", n)).is_ok());
            assert!(tab.push("state", msg("state", n)).is_ok());
        }
        assert!(tab.send(msg("result", 0)).is_ok());
        let all = tab.take().unwrap_or_default();
        // The newest state, the answer after it, the drop count, the
        // newest telemetry.
        assert_eq!(all.len(), 1 + 1 + 1 + TAB_TELEMETRY);
        assert_eq!(all[0], msg("state", 999));
        assert_eq!(all[1], msg("result", 0));
        assert_eq!(
            all[2],
            serde_json::json!({ "type": "page", "dropped": 1000 - TAB_TELEMETRY }).to_string()
        );
        assert_eq!(all[all.len() - 1], msg("telemetry", 999));
        // Events pile up: the page is closed, and nothing more is kept.
        for n in 0..=TAB_EVENTS {
            let _ = tab.push("hop", msg("hop", n));
        }
        assert!(tab.closed() && tab.take().is_none() && tab.push("hop", msg("hop", 0)).is_err());
    }

    /// A state from before the robot was lost must not be sent after the
    /// `lost` that came later: the page would show the stale state over
    /// "robot lost". Events and state messages go in the order they came.
    #[test]
    fn a_state_queued_before_an_event_is_sent_before_it() {
        let tab = Tab::default();
        let msg = |kind: &str, n: usize| serde_json::json!({ "type": kind, "n": n }).to_string();
        assert!(tab.push("state", msg("state", 1)).is_ok());
        assert!(tab.push("lost", msg("lost", 2)).is_ok());
        assert_eq!(
            tab.take().unwrap_or_default(),
            [msg("state", 1), msg("lost", 2)]
        );
        // A state that comes after an event follows it, the newest only.
        assert!(tab.push("notice", msg("notice", 3)).is_ok());
        assert!(tab.push("state", msg("state", 4)).is_ok());
        assert!(tab.push("state", msg("state", 5)).is_ok());
        assert_eq!(
            tab.take().unwrap_or_default(),
            [msg("notice", 3), msg("state", 5)]
        );
    }
}
